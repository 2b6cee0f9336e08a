"""OpenFOAM case (``--format openfoam -o CASE``): ``CASE/constant/polyMesh`` and an empty
``CASE/CASE.foam`` for ParaView; and, where the case has none, ``system/controlDict``,
``fvSchemes`` and ``fvSolution`` (set up for ``potentialFoam``), without which no OpenFOAM tool
(checkMesh included) opens a case. Where the case has no ``0/`` and the patches include an inlet
and an outlet (``meshgen.geometry.patches.flow_role``: ``patch``-type patches named inlet/inflow and
outlet/outflow), ``0/U`` and ``0/p`` for potential flow too: 1 m/s into the domain normal to the
inlet, p = 0 on the outlet, slip walls, symmetry and empty as their types, zero gradient on any
other patch. Re-meshing a case keeps the user's ``system/`` files; of ``0/U`` and ``0/p`` it
rewrites meshgen's own (also after a solver has solved them) and keeps a user's edits, with one
warning (``meshgen.formats._foam_fields``).

polyMesh, as OpenFOAM's own utilities write it (label 32 bits, scalar 64 bits, little-endian):

- ``points``: the nodes in C order of the node array (k fastest).
- ``faces``: internal faces first, in upper-triangular order (by owner cell, then neighbour), then
  the boundary faces patch by patch. Each face's nodes go round so that its right-hand normal
  points out of its owner (the lower-numbered cell; on the boundary, out of the domain).
- ``owner``, ``neighbour``: cells are numbered in C order of the cells (i, j, k).
- ``boundary``: the patches with ``type`` (wall, patch, symmetry, empty), ``nFaces``, ``startFace``.
- ``meshgen.json`` (ignored by OpenFOAM): the node-array shape, whether the mesh is a 2D one
  extruded, and meshgen's metadata; the reader uses it to give the structured grid back.

Binary files store each list as ``N (`` raw bytes ``)``; faces as OpenFOAM's faceCompactList (the
offsets, then the node labels). ASCII files are what ``foamFormatConvert`` would make of them.

A 2D mesh (n1+1, n2+1, 2) is extruded one cell along +z, as thick as its typical cell
(sqrt(area / cells)); the front (z = 0) and back faces form the ``empty`` patch ``frontAndBack``.
A cell's faces are oriented from the sign of the map's total volume, so a left-handed map still
gives outward normals.
"""

from __future__ import annotations

import json
import os
import re
import warnings
from pathlib import Path

import numpy as np

from meshgen.errors import FormatError, MeshgenWarning, excerpt
from meshgen.formats._foam_fields import field_record, fields_to_write, kept_warning, previous_fields, starting_fields
from meshgen.formats._foam_topology import boundary_owner, internal_faces, patch_entries, poly_mesh_note
from meshgen.formats._structured import boundary_elements, orientation, write_rows
from meshgen.formats.metadata import METADATA_KEY, metadata_json
from meshgen.geometry import cube
from meshgen.geometry.grid import cell_connectivity
from meshgen.geometry.patches import Patch, flow_role
from meshgen.run.atomic import atomic_path
from meshgen.run.inputs import InputError, read_input_bytes
from meshgen.run.publish import publishing, remove_stale_temporaries

__all__ = [
    "CONTROL_DICT",
    "EXTRUDED_PATCH",
    "FV_SCHEMES",
    "FV_SOLUTION",
    "HEADER",
    "LABEL_LIMIT",
    "RECORD_NAME",
    "WORD",
    "TOPOLOGY_BLOCK",
    "case_folder",
    "check_extrusion_patch",
    "check_node_shape",
    "check_topology",
    "check_output",
    "check_patch_name",
    "extrude",
    "extrusion_thickness",
    "foam_header",
    "poly_mesh_folder",
    "read",
    "read_boundary",
    "read_list",
    "read_patches",
    "signed_area",
    "write",
    "write_boundary",
    "write_case",
    "write_list",
]

HEADER = """/*--------------------------------*- C++ -*----------------------------------*\\
  Written by meshgen
\\*---------------------------------------------------------------------------*/
FoamFile
{{
    version     2.0;
    format      {format};
    arch        "LSB;label=32;scalar=64";
    class       {class_name};
    location    "{location}";
    object      {object_name};{note}
}}
// ************************************************************************* //

"""
EXTRUDED_PATCH = "frontAndBack"
RECORD_NAME = "meshgen.json"
WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_.:+-]*")
LABEL_LIMIT = 2**31 - 1
CONTROL_DICT = """application     potentialFoam;
startFrom       latestTime;
startTime       0;
stopAt          endTime;
endTime         1;
deltaT          1;
writeControl    timeStep;
writeInterval   1;
writeFormat     ascii;
writePrecision  12;
runTimeModifiable false;
"""
FV_SCHEMES = """ddtSchemes      { default steadyState; }
gradSchemes     { default Gauss linear; }
divSchemes      { default none; div(phi,U) bounded Gauss linearUpwind grad(U); div(div(phi,U)) Gauss linear; }
laplacianSchemes { default Gauss linear corrected; }
interpolationSchemes { default linear; }
snGradSchemes   { default corrected; }
"""
FV_SOLUTION = """solvers
{
    "(Phi|p)" { solver GAMG; smoother DIC; tolerance 1e-08; relTol 0; }
    U { solver smoothSolver; smoother symGaussSeidel; tolerance 1e-08; relTol 0.1; }
}
potentialFlow { nNonOrthogonalCorrectors 5; }
"""


# --- the target ----------------------------------------------------------------------------


def case_folder(path) -> Path:
    """The case folder of ``path``: ``CASE`` or ``CASE/constant/polyMesh`` or ``CASE/CASE.foam``."""
    path = Path(path)
    if path.parts[-2:] == ("constant", "polyMesh"):
        return path.parent.parent
    if path.suffix == ".foam":
        return path.parent
    return path


def check_output(path) -> Path:
    """The case folder to write, checked before any work: a folder that does not exist yet (in an
    existing writable folder), or an existing case folder (empty, or with system/ or constant/).
    MeshgenError otherwise."""
    case = case_folder(path)
    if case.exists():
        if not case.is_dir():
            raise FormatError(f"OpenFOAM target {case} exists and is not a folder")
        entries = {entry.name for entry in case.iterdir()}
        if entries and not ({"system", "constant"} & entries):
            raise FormatError(f"OpenFOAM target {case} exists and is not a case folder (no system/ or constant/ in it)")
        for sub in ("constant", "system", "constant/polyMesh"):
            if (case / sub).exists() and not (case / sub).is_dir():
                raise FormatError(f"OpenFOAM target {case}: {case / sub} is not a folder")
        if not os.access(case, os.W_OK | os.X_OK):
            raise FormatError(f"OpenFOAM case {case} is not writable")
    else:
        parent = case.parent if str(case.parent) else Path(".")
        if not parent.is_dir():
            raise FormatError(f"output folder {parent} does not exist")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise FormatError(f"output folder {parent} is not writable")
    return case


def check_patch_name(name: str) -> None:
    if not WORD.fullmatch(name):
        raise FormatError(f"patch name '{name}' is not an OpenFOAM word (a letter or _ first, then letters, digits, _ . : + -)")


# --- writing ---------------------------------------------------------------------------------


def write(case, X, cell_data, metadata, patches, binary: bool = True) -> None:
    """Write node array ``X`` (n1+1, n2+1[, n3+1], dim) as ``case/constant/polyMesh`` with the
    boundary ``patches`` (``meshgen.geometry.patches.Patch``), atomically: the new polyMesh is written beside
    the old one and swapped in. ``cell_data`` has no place in a polyMesh and is not written."""
    check_extrusion_patch(patches, X.shape[-1])
    X3 = extrude(X) if X.shape[-1] == 2 else X
    write_case(
        case, X.shape[:-1], metadata, patches, lambda folder, all_patches: _write_poly_mesh(folder, X3, all_patches, binary)
    )


def check_node_shape(node_shape, path=None) -> None:
    """FormatError when a mesh of ``node_shape`` nodes (2D: extruded) overflows OpenFOAM's 32-bit labels."""
    points = int(np.prod(node_shape)) * (2 if len(node_shape) == 2 else 1)
    if points * 3 > LABEL_LIMIT:
        raise FormatError(f"mesh too large for 32-bit OpenFOAM labels: {points} points")


def check_extrusion_patch(patches, dim: int) -> None:
    """FormatError when a 2D mesh's patches take the name of the extrusion's front and back."""
    if dim == 2 and any(patch.name == EXTRUDED_PATCH for patch in patches):
        raise FormatError(f"patch name '{EXTRUDED_PATCH}' is the front and back of an extruded 2D mesh: pick another")


def write_case(case, node_shape, metadata, patches, write_poly_mesh, block_set: str | None = None) -> None:
    """Write the case of a mesh of ``node_shape`` nodes (2D: extruded one cell) with ``patches``:
    ``write_poly_mesh(folder, patches)`` fills a new polyMesh folder (the patches with the
    extrusion's ``frontAndBack`` in 2D), which is swapped in atomically with the system files,
    the starting fields and meshgen's record, in one publication.

    ``block_set``: the name of the block set whose merged mesh this is (``node_shape`` then gives
    only the dimension, e.g. ``(0, 0, 0)``): the record says ``"block_set"`` instead of a
    ``node_shape`` the structured reader would rebuild a grid from."""
    case = Path(case)
    shape = [int(n) for n in node_shape]
    dim = len(shape)
    check_extrusion_patch(patches, dim)
    if dim == 2:
        patches = list(patches) + [_extrusion_patch()]
    if block_set is None:
        check_node_shape(shape)
    fields = starting_fields(patches, foam_header) if _has_inlet_and_outlet(patches) else {}
    write_fields, kept = fields_to_write(case / "0", fields, previous_fields(case / "constant" / "polyMesh" / RECORD_NAME))
    # The record names the fields as meshgen writes them, kept ones included: a kept field is the
    # user's, so it stays unlike the recorded text until the user deletes it.
    grid = f'"node_shape": {shape}' if block_set is None else f'"block_set": {json.dumps(block_set)}'
    record = (
        f'{{{grid}, "extruded_2d": {json.dumps(dim == 2)}, "fields": {json.dumps(field_record(write_fields))}, '
        f'"metadata": {metadata_json(metadata)}}}'
    )

    # Inside the publication of write_mesh (meshgen.run.publish): the polyMesh, the system files and
    # the starting fields are staged and take their names together under the case's lock; a
    # failure removes what this run staged and the folders it made, never another run's.
    with publishing(case, FormatError) as publication:
        remove_stale_temporaries(case)
        for folder in (case, case / "constant", case / "system"):
            publication.make_folder(folder)
            remove_stale_temporaries(folder)
        with atomic_path(case / "constant" / "polyMesh", folder=True) as temporary:
            write_poly_mesh(temporary, patches)
            (temporary / RECORD_NAME).write_text(record)
        for name, text in (("controlDict", CONTROL_DICT), ("fvSchemes", FV_SCHEMES), ("fvSolution", FV_SOLUTION)):
            _write_if_missing(case / "system" / name, foam_header("dictionary", "system", name) + text)
        if write_fields:
            publication.make_folder(case / "0")
            for name, text in write_fields.items():
                with atomic_path(case / "0" / name) as temporary:
                    temporary.write_text(text)
        _write_if_missing(case / f"{case.resolve().name}.foam", "")
    if kept:
        warnings.warn(kept_warning(case, kept), MeshgenWarning, stacklevel=2)


def extrude(X: np.ndarray, thickness: float | None = None) -> np.ndarray:
    """A 2D node array (n1+1, n2+1, 2) as a 3D one (n1+1, n2+1, 2, 3): z = 0 and z = ``thickness``
    (default the typical cell size ``extrusion_thickness``)."""
    if thickness is None:
        thickness = extrusion_thickness(signed_area(X), (X.shape[0] - 1) * (X.shape[1] - 1))
    X3 = np.empty(X.shape[:2] + (2, 3))
    X3[..., :2] = X[:, :, None, :]
    X3[:, :, 0, 2] = 0.0
    X3[:, :, 1, 2] = thickness
    return X3


def signed_area(X: np.ndarray) -> float:
    """The signed area of the cells of a 2D node array (n1+1, n2+1, 2): the shoelace area of each
    cell as two triangles, summed (a slab of rows gives its share)."""
    x, y = X[..., 0], X[..., 1]
    return float(
        0.5
        * np.sum((x[1:, 1:] - x[:-1, :-1]) * (y[:-1, 1:] - y[1:, :-1]) - (x[:-1, 1:] - x[1:, :-1]) * (y[1:, 1:] - y[:-1, :-1]))
    )


def extrusion_thickness(area: float, cells: int) -> float:
    """The thickness of an extruded 2D mesh: its typical cell size sqrt(|area| / cells) (1 for none)."""
    return float(np.sqrt(abs(area) / cells)) or 1.0


def _extrusion_patch():
    return Patch(EXTRUDED_PATCH, "empty", ("zeta0", "zeta1"))


def write_boundary(folder: Path, entries) -> None:
    """The polyMesh ``boundary`` file of ``entries`` [(name, type, nFaces, startFace)]."""
    lines = [foam_header("polyBoundaryMesh", "constant/polyMesh", "boundary"), f"{len(entries)}\n(\n"]
    for name, kind, count, first in entries:
        group = f"        inGroups        1({kind});\n" if kind in ("wall", "empty", "symmetry") else ""
        lines.append(
            f"    {name}\n    {{\n        type            {kind};\n{group}"
            f"        nFaces          {count};\n        startFace       {first};\n    }}\n"
        )
    lines.append(")\n\n// ************************************************************************* //\n")
    (folder / "boundary").write_text("".join(lines))


def _write_poly_mesh(folder: Path, X3, patches, binary: bool) -> None:
    node_shape = X3.shape[:-1]
    cell_shape = tuple(n - 1 for n in node_shape)
    point_ids = np.arange(np.prod(node_shape), dtype=np.int32).reshape(node_shape)
    cell_ids = np.arange(np.prod(cell_shape), dtype=np.int32).reshape(cell_shape)
    positive = orientation(X3) > 0
    internal_nodes, internal_owner, internal_neighbour = internal_faces(point_ids, cell_ids, positive)
    boundary_nodes, boundary_owners = [], []
    for patch in patches:
        for face_name in patch.faces:
            boundary_nodes.append(boundary_elements(node_shape, face_name, positive).astype(np.int32))
            boundary_owners.append(boundary_owner(cell_shape, face_name))

    faces = np.concatenate([internal_nodes, *boundary_nodes])
    owner = np.concatenate([internal_owner, *boundary_owners])
    note = poly_mesh_note(node_shape)
    fmt = "binary" if binary else "ascii"
    points = X3.reshape(-1, 3)
    with open(folder / "points", "wb") as file:
        file.write(foam_header("vectorField", "constant/polyMesh", "points", fmt).encode())
        write_list(file, points, binary, "({} {} {})")
    with open(folder / "faces", "wb") as file:
        if binary:
            file.write(foam_header("faceCompactList", "constant/polyMesh", "faces", fmt).encode())
            write_list(file, np.arange(0, 4 * len(faces) + 1, 4, dtype=np.int32), True)
            write_list(file, faces.reshape(-1), True)
        else:
            file.write(foam_header("faceList", "constant/polyMesh", "faces", fmt).encode())
            write_list(file, faces, False, "4({} {} {} {})")
    for name, labels in (("owner", owner), ("neighbour", internal_neighbour)):
        with open(folder / name, "wb") as file:
            file.write(foam_header("labelList", "constant/polyMesh", name, fmt, note).encode())
            write_list(file, labels, binary, "{}")
    write_boundary(folder, patch_entries(node_shape, patches))


def foam_header(class_name, location, object_name, fmt="ascii", note="") -> str:
    note = f'\n    note        "{note}";' if note else ""
    return HEADER.format(format=fmt, class_name=class_name, location=location, object_name=object_name, note=note)


def write_list(file, values: np.ndarray, binary: bool, row: str = "{}") -> None:
    """An OpenFOAM list: ``N`` then ``(`` raw little-endian bytes ``)`` (binary) or one row per
    line (ASCII, ``row`` formats one entry's values)."""
    count = len(values)
    if binary:
        data = np.ascontiguousarray(values, dtype="<f8" if values.dtype.kind == "f" else "<i4")
        file.write(f"{count}\n(".encode())
        file.write(memoryview(data).cast("B"))
        file.write(b")\n\n")
        return
    file.write(f"{count}\n(\n".encode())
    write_rows(file, values, row)
    file.write(b")\n\n")


def _has_inlet_and_outlet(patches) -> bool:
    roles = {flow_role(patch) for patch in patches}
    return {"inflow", "outflow"} <= roles


def _write_if_missing(path: Path, text: str) -> None:
    if path.exists():
        return
    with atomic_path(path, keep_existing=True) as temporary:
        temporary.write_text(text)


# --- reading ---------------------------------------------------------------------------------


def poly_mesh_folder(path) -> Path:
    case = case_folder(path)
    folder = case / "constant" / "polyMesh"
    if not folder.is_dir():
        raise FormatError(f"{path}: no constant/polyMesh in the case {case}")
    return folder


def read_list(path: Path, dtype: str) -> np.ndarray:
    """The list (ASCII or binary) of an OpenFOAM polyMesh file, ``dtype`` "points" (N, 3) float64,
    "faces" (N, 4) int64 (quadrilaterals only; a faceCompactList is expanded) or "labels" (N,)
    int64."""
    data = _input_bytes(path)
    header_end = data.find(b"}", data.find(b"FoamFile"))
    if header_end < 0:
        raise FormatError(f"{path}: no FoamFile header")
    header = data[:header_end].decode("ascii", "replace")
    binary = re.search(r"format\s+binary\s*;", header) is not None
    class_name = (re.search(r"class\s+(\w+)\s*;", header) or [None, ""])[1]
    position = header_end + 1

    def next_list(position):
        match = re.compile(rb"(\d+)\s*\(").search(data, position)
        if match is None:
            raise FormatError(f"{path}: no list found")
        return int(match[1]), match.end()

    count, position = next_list(position)
    if binary:
        item = np.dtype("<f8") if dtype == "points" else np.dtype("<i4")
        width = 3 if dtype == "points" else 1
        values = np.frombuffer(data, dtype=item, count=count * width, offset=position)
        if class_name == "faceCompactList":
            offsets = values.astype(np.int64)
            count2, position2 = next_list(position + values.nbytes + 1)
            labels = np.frombuffer(data, dtype="<i4", count=count2, offset=position2).astype(np.int64)
            if np.any(np.diff(offsets) != 4):
                raise FormatError(f"{path}: faces that are not quadrilaterals (meshgen reads hexahedral meshes)")
            return labels.reshape(-1, 4)
        return values.reshape(-1, 3).astype(float) if width == 3 else values.astype(np.int64)
    end = data.rfind(b")")
    tokens = data[position:end].replace(b"(", b" ").replace(b")", b" ").split()
    if dtype == "points":
        return np.array(tokens, dtype=float).reshape(count, 3)
    numbers = np.array(tokens, dtype=np.int64)
    if dtype == "faces":
        rows = numbers.reshape(count, 5)
        if np.any(rows[:, 0] != 4):
            raise FormatError(f"{path}: faces that are not quadrilaterals (meshgen reads hexahedral meshes)")
        return rows[:, 1:]
    return numbers.reshape(count)


def _record(folder: Path) -> dict:
    path = folder / RECORD_NAME
    if not path.is_file():
        raise FormatError(f"{folder}: no {RECORD_NAME}: meshgen reads the OpenFOAM cases it wrote (their structured grid)")
    try:
        record = json.loads(_input_bytes(path, limit=16 * 2**20))
    except ValueError as exc:
        raise FormatError(f"{path}: {excerpt(exc)}") from None
    if isinstance(record, dict) and "block_set" in record:
        raise FormatError(
            f"{folder}: the merged mesh of the block set {excerpt(repr(record['block_set']))}: meshgen reads back the "
            "structured grid of single-block cases; read the block set's .cgns (a zone per block), or check the case with checkMesh"
        )
    shape = record.get("node_shape") if isinstance(record, dict) else None
    if not (isinstance(shape, list) and len(shape) in (2, 3) and all(isinstance(n, int) and n >= 2 for n in shape)):
        raise FormatError(f"{path}: no node_shape of 2 or 3 counts of at least 2: not a case meshgen wrote")
    return record


def read(path):
    """Read a case meshgen wrote (its folder, ``.foam`` file or ``constant/polyMesh``) as a
    ``meshio.Mesh``: the points of ``points``, hexahedron cells (a 2D mesh: the quads of its
    front, z = 0) in C order of the cells, meshgen's metadata in field data."""
    import meshio

    folder = poly_mesh_folder(path)
    record = _record(folder)
    node_shape = tuple(int(n) for n in record["node_shape"])
    extruded = bool(record.get("extruded_2d"))
    points = read_list(folder / "points", "points")
    expected = int(np.prod(node_shape)) * (2 if extruded else 1)
    if len(points) != expected:
        raise FormatError(f"{folder}: {len(points)} points where {RECORD_NAME} says {expected}")
    check_topology(folder, node_shape + (2,) if extruded else node_shape)
    if extruded:
        points = np.column_stack([points[0::2, :2], np.zeros(len(points) // 2)])  # the front, z = 0
    cell_type = "quad" if extruded else "hexahedron"
    field_data = {}
    if record.get("metadata"):
        field_data[METADATA_KEY] = np.frombuffer(metadata_json(record["metadata"]).encode(), dtype=np.uint8).copy()
    return meshio.Mesh(points, [(cell_type, cell_connectivity(node_shape))], field_data=field_data)


def _input_bytes(path: Path, limit: int = 2**40) -> bytes:
    """The bytes of a case file (a regular file, at most ``limit`` bytes: ``meshgen.run.inputs``)."""
    try:
        return read_input_bytes(path, "case file", limit)
    except InputError as exc:
        raise FormatError(str(exc)) from None


TOPOLOGY_BLOCK = 2**20  # faces checked at a time


def check_topology(folder: Path, shape3: tuple) -> None:
    """FormatError unless ``faces``, ``owner`` and ``neighbour`` are those of the structured grid
    of nodes ``shape3`` (i, j, k) that the reader rebuilds from ``points``: every internal face the
    4 nodes shared by its owner and its neighbour (owner < neighbour), every boundary face 4 nodes
    of its owner on one boundary plane, each cell pair and each boundary cell face once. The
    readers verify what they do not compute; checkMesh checks the geometry."""
    faces = read_list(folder / "faces", "faces")
    owner = read_list(folder / "owner", "labels")
    neighbour = read_list(folder / "neighbour", "labels")
    nodes = np.array(shape3)
    cells = nodes - 1
    internal = int(sum(np.prod(cells) // cells[a] * (cells[a] - 1) for a in range(3)))
    boundary = int(sum(2 * np.prod(cells) // cells[a] for a in range(3)))
    if len(neighbour) != internal or len(faces) != internal + boundary or len(owner) != len(faces):
        raise FormatError(
            f"{folder}: {len(faces)} faces, {len(owner)} owners and {len(neighbour)} neighbours where the "
            f"{' x '.join(map(str, cells))} grid has {internal + boundary} faces, {internal} of them internal"
        )
    if faces.min() < 0 or faces.max() >= np.prod(nodes) or owner.min() < 0 or owner.max() >= np.prod(cells):
        raise FormatError(f"{folder}: face or owner labels outside the grid")
    if len(neighbour) and (neighbour.min() < 0 or neighbour.max() >= np.prod(cells)):
        raise FormatError(f"{folder}: neighbour labels outside the grid")
    for start in range(0, len(faces), TOPOLOGY_BLOCK):
        stop = min(len(faces), start + TOPOLOGY_BLOCK)
        node_ijk = np.stack(np.unravel_index(faces[start:stop], shape3), axis=-1)  # (F, 4, 3)
        owner_ijk = np.stack(np.unravel_index(owner[start:stop], tuple(cells)), axis=-1)[:, None]
        offset = node_ijk - owner_ijk
        good = np.all((offset == 0) | (offset == 1), axis=(1, 2))
        ordered = np.sort(faces[start:stop], axis=1)
        good &= np.all(np.diff(ordered, axis=1) > 0, axis=1)  # four distinct nodes
        inside = min(stop, internal) - start
        if inside > 0:  # the internal ones: in the neighbour too, which comes after the owner
            mine = slice(0, inside)
            other = np.stack(np.unravel_index(neighbour[start : start + inside], tuple(cells)), axis=-1)[:, None]
            shared = node_ijk[mine] - other
            good[mine] &= np.all((shared == 0) | (shared == 1), axis=(1, 2))
            good[mine] &= owner[start : start + inside] < neighbour[start : start + inside]
        if stop > internal:  # the boundary ones: on one plane i, j or k = 0 or last
            rest = slice(max(0, internal - start), stop - start)
            ijk = node_ijk[rest]
            on_plane = np.zeros(len(ijk), dtype=bool)
            for axis in range(3):
                column = ijk[:, :, axis]
                on_plane |= np.all(column == 0, axis=1) | np.all(column == shape3[axis] - 1, axis=1)
            good[rest] &= on_plane
        if not good.all():
            face = start + int(np.argmin(good))
            kind = "internal" if face < internal else "boundary"
            raise FormatError(
                f"{folder}: {kind} face {face} (nodes {faces[face].tolist()}, owner {owner[face]}) is not a face of its "
                "cells in the structured grid: faces, owner or neighbour are corrupt"
            )
    pairs = owner[:internal] * np.prod(cells) + neighbour
    if len(np.unique(pairs)) != internal or len(np.unique(np.sort(faces[internal:], axis=1), axis=0)) != boundary:
        raise FormatError(f"{folder}: a face is listed twice: faces, owner or neighbour are corrupt")


def read_boundary(folder: Path) -> list[tuple[str, str, int, int]]:
    """(name, type, nFaces, startFace) of each entry of ``boundary``."""
    text = _input_bytes(folder / "boundary").decode("utf-8", "replace")
    text = text[text.find("}", text.find("FoamFile")) + 1 :]
    entries = []
    for name, body in re.findall(r"([^\s{}()]+)\s*\{([^}]*)\}", text):
        fields = dict(re.findall(r"(\w+)\s+([^;]+);", body))
        entries.append((name, fields["type"].strip(), int(fields["nFaces"]), int(fields["startFace"])))
    return entries


def read_patches(path) -> list:
    """The patches of a case meshgen wrote: each boundary entry's faces located on the cube faces
    from their node labels (a 2D mesh: the extrusion's front and back left out)."""
    folder = poly_mesh_folder(path)
    record = _record(folder)
    node_shape = tuple(int(n) for n in record["node_shape"])
    dim = len(node_shape)
    shape3 = node_shape + (2,) if record.get("extruded_2d") else node_shape
    faces = read_list(folder / "faces", "faces")
    index = np.stack(np.unravel_index(faces, shape3), axis=-1)  # (faces, 4, 3): i, j, k of each node
    patches = []
    for name, kind, count, start in read_boundary(folder):
        nodes = index[start : start + count]
        found = []
        for face in cube.faces(3):
            plane = shape3[face.axis] - 1 if face.side else 0
            on = np.all(nodes[:, :, face.axis] == plane, axis=1)
            if on.any():
                found.append((face, int(on.sum())))
        if sum(n for _, n in found) != count:
            raise FormatError(f"{folder}: patch '{name}' has faces off the grid's boundary")
        names = tuple(face.name for face, _ in found if face.axis < dim)
        if names:
            patches.append(Patch(name, kind, names))
    return patches
