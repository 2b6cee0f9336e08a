"""Gmsh MSH 4.1 (.msh, ASCII) with physical groups: ``domain`` for the cells (3D: a volume, 2D: a
surface) and one per patch for its boundary elements (3D: quadrangles, 2D: lines).

Entities: one per cube face (tags 1 .. 2*dim, in cube face order: xi0, xi1, eta0, ...), each in
the physical group of its patch, and the domain (tag 1), bounded by them; a block set's merged mesh
(``write_elements``): one entity per patch, its faces recorded as ``block.face``. All nodes are listed
once, classified on the domain; elements are numbered cells first, then the faces. meshgen's
metadata sits in a ``$meshgen`` section (``{}`` without metadata) and the patch types in
``$meshgenPatches``, sections Gmsh and meshio skip.

    $MeshFormat 4.1 0 8
    $PhysicalNames   dim tag "name": the patches (dim - 1, tags 2, 3, ...), domain (dim, tag 1)
    $Entities        0 points, then (2D) curves + a surface or (3D) 0 curves, surfaces + a volume
    $Nodes           one block: every node, tags 1..N in C order of the node array
    $Elements        the cells (type 5 hexahedron, 3 quadrangle; Gmsh's corner order is VTK's),
                     then a block per cube face (type 3 quadrangle, 1 line), outward normals
"""

from __future__ import annotations

import json

import numpy as np

from meshgen.errors import FormatError
from meshgen.formats._structured import boundary_elements, orientation, write_rows
from meshgen.formats.metadata import METADATA_KEY, metadata_json
from meshgen.formats.streamed import bounding_box, cell_slabs, cells_of_slab, map_orientation
from meshgen.geometry import cube
from meshgen.geometry.grid import cell_connectivity
from meshgen.geometry.patches import Patch, as_records

__all__ = [
    "DOMAIN_NAME",
    "PATCHES_SECTION",
    "check_patch_name",
    "read",
    "read_patches",
    "write",
    "write_elements",
    "write_parts",
    "write_streamed",
]

DOMAIN_NAME = "domain"
PATCHES_SECTION = "meshgenPatches"  # the patch types, which MSH has no place for
GMSH_HEXAHEDRON, GMSH_QUADRANGLE, GMSH_LINE = 5, 3, 1
PART_ROWS = 1 << 20  # node tags written per part


def check_patch_name(name: str) -> None:
    if name == DOMAIN_NAME:
        raise FormatError(f"patch name '{DOMAIN_NAME}' is the .msh file's physical group of the cells: pick another")


def write(path, X, cell_data, metadata, patches):
    """Write node array ``X`` with physical groups; ``cell_data`` is not written."""
    node_shape = X.shape[:-1]
    dim = len(node_shape)
    group_of = {face: number for number, patch in enumerate(patches) for face in patch.faces}
    positive = orientation(X) > 0
    entities = [(group_of[face.name], boundary_elements(node_shape, face.name, positive)) for face in cube.faces(dim)]
    write_elements(
        path,
        X.reshape(-1, dim),
        cell_connectivity(node_shape),
        [p.name for p in patches],
        entities,
        metadata,
        as_records(patches),
    )


def write_elements(path, points, cells, group_names, entities, metadata, records) -> None:
    """Write an unstructured mesh: ``points`` (N, dim), ``cells`` (M, 8) hexahedra or (M, 4)
    quads (VTK corner order, 0-based), the physical groups ``group_names`` of the boundary and
    ``entities`` [(group number, elements)], one boundary entity each (elements (F, 4) quads with
    outward normals or (E, 2) segments, 0-based); ``records``: the patches' records for the
    ``$meshgenPatches`` section."""
    box = (points.min(axis=0), points.max(axis=0))
    write_parts(path, len(points), [points], box, len(cells), [cells], group_names, entities, metadata, records)


def write_parts(path, point_count, point_parts, box, cell_count, cell_parts, group_names, entities, metadata, records) -> None:
    """``write_elements`` with the points and cells given in consecutive parts (iterables of
    (n, dim) and (m, corners) arrays, 0-based labels) and the points' bounding box (low, high)
    given ahead: a mesh larger than memory is written part by part."""
    dim = len(box[0])
    low, high = np.pad(box[0], (0, 3 - dim)), np.pad(box[1], (0, 3 - dim))
    box = " ".join(f"{v:.17g}" for v in (*low, *high))
    with open(path, "wb") as file:
        lines = ["$MeshFormat", "4.1 0 8", "$EndMeshFormat", "$PhysicalNames", str(len(group_names) + 1)]
        lines += [f'{dim - 1} {2 + n} "{name}"' for n, name in enumerate(group_names)]
        lines += [f'{dim} 1 "{DOMAIN_NAME}"', "$EndPhysicalNames", "$Entities"]
        lines.append(f"0 {len(entities)} 1 0" if dim == 2 else f"0 0 {len(entities)} 1")
        for number, (group, _) in enumerate(entities, start=1):  # each boundary entity: box, group, no bounding entities
            lines.append(f"{number} {box} 1 {2 + group} 0")
        bounding = " ".join(str(n) for n in range(1, len(entities) + 1))
        lines += [f"1 {box} 1 1 {len(entities)} {bounding}", "$EndEntities", "$Nodes"]
        lines += [f"1 {point_count} 1 {point_count}", f"{dim} 1 0 {point_count}", ""]
        file.write("\n".join(lines).encode())
        for first in range(1, point_count + 1, PART_ROWS):
            write_rows(file, np.arange(first, min(first + PART_ROWS, point_count + 1)), "{}")
        for points in point_parts:
            write_rows(file, np.pad(points, ((0, 0), (0, 3 - dim))), "{} {} {}")
        boundary = [elements + 1 for _, elements in entities]
        total = cell_count + sum(len(b) for b in boundary)
        file.write(f"$EndNodes\n$Elements\n{1 + len(entities)} {total} 1 {total}\n".encode())
        file.write(f"{dim} 1 {GMSH_HEXAHEDRON if dim == 3 else GMSH_QUADRANGLE} {cell_count}\n".encode())
        first = 1
        for cells in cell_parts:
            tags = np.arange(first, first + len(cells))
            write_rows(file, np.column_stack([tags, cells + 1]), " ".join(["{}"] * (cells.shape[1] + 1)))
            first += len(cells)
        for number, elements in enumerate(boundary, start=1):
            file.write(f"{dim - 1} {number} {GMSH_QUADRANGLE if dim == 3 else GMSH_LINE} {len(elements)}\n".encode())
            tags = np.arange(first, first + len(elements))
            write_rows(file, np.column_stack([tags, elements]), " ".join(["{}"] * (elements.shape[1] + 1)))
            first += len(elements)
        file.write(b"$EndElements\n")
        # Always present (an empty {} without metadata): it marks the file as meshgen's, whose
        # boundary elements are its patches rather than cells to evaluate.
        file.write(f"$meshgen\n{metadata_json(metadata)}\n$Endmeshgen\n".encode())
        file.write(f"${PATCHES_SECTION}\n{json.dumps(records)}\n$End{PATCHES_SECTION}\n".encode())


def write_streamed(path, nodes, metadata, patches) -> None:
    """``write`` of the mesh in ``nodes`` (``meshgen.formats.streamed.NodeFile``), slab by slab:
    the bounding box and orientation first (a reading pass), then points and cells by i-slabs."""
    node_shape, dim = nodes.node_shape, nodes.dim
    group_of = {face: number for number, patch in enumerate(patches) for face in patch.faces}
    positive = map_orientation(nodes) > 0
    entities = [(group_of[face.name], boundary_elements(node_shape, face.name, positive)) for face in cube.faces(dim)]
    point_parts = (nodes.read(0, part).reshape(-1, dim) for part in nodes.slabs(0))
    cell_parts = (cells_of_slab(node_shape, part) for part in cell_slabs(node_shape, nodes.block_nodes))
    cell_count = int(np.prod([n - 1 for n in node_shape]))
    names, records = [p.name for p in patches], as_records(patches)
    write_parts(
        path,
        int(np.prod(node_shape)),
        point_parts,
        bounding_box(nodes),
        cell_count,
        cell_parts,
        names,
        entities,
        metadata,
        records,
    )


def _section(path, name: str) -> str | None:
    with open(path, "rb") as file:
        data = file.read()
    start = data.find(f"${name}\n".encode())
    if start < 0:
        return None
    end = data.find(f"$End{name}".encode(), start)
    return data[start + len(name) + 2 : end].decode().strip()


def read(path):
    """Read with meshio; a file meshgen wrote (it has a ``$meshgen`` section) keeps only its cells
    (hexahedra or quads, not the patches' boundary elements) and gives its metadata back."""
    import meshio

    mesh = meshio.read(path, file_format="gmsh")
    text = _section(path, METADATA_KEY)
    if text is None:  # a foreign file: as meshio reads it (evaluate reports other cell types as skipped)
        return mesh
    volume = "hexahedron" if any(block.type == "hexahedron" for block in mesh.cells) else "quad"
    blocks = [block.data for block in mesh.cells if block.type == volume]
    field_data = {}
    if text not in ("", "{}"):
        field_data[METADATA_KEY] = np.frombuffer(text.encode(), dtype=np.uint8).copy()
    return meshio.Mesh(np.asarray(mesh.points, dtype=float), [(volume, np.concatenate(blocks))], field_data=field_data)


def read_patches(path) -> list:
    """The patches of a .msh file meshgen wrote: names from $PhysicalNames, faces from the face
    entities' physical tags in $Entities (entity n is the n-th cube face), types from
    ``$meshgenPatches``."""
    names = _section(path, "PhysicalNames")
    entities = _section(path, "Entities")
    recorded = _section(path, PATCHES_SECTION)
    if names is None or entities is None or recorded is None:
        raise FormatError(f"{path}: no $PhysicalNames, $Entities or ${PATCHES_SECTION} (not written by meshgen)")
    groups = {}
    for line in names.splitlines()[1:]:
        dim, tag, name = line.split(maxsplit=2)
        groups[(int(dim), int(tag))] = name.strip('"')
    rows = entities.splitlines()
    counts = [int(n) for n in rows[0].split()]
    dim = 3 if counts[3] else 2
    first = 1 + (counts[1] if dim == 3 else 0)  # after the counts (and, in 3D, the curves: none)
    face_rows = rows[first : first + counts[dim - 1]]
    types = {record["name"]: record["type"] for record in json.loads(recorded)}
    if any("." in face for record in json.loads(recorded) for face in record["faces"]):  # a block set's merged mesh
        return [Patch(r["name"], r["type"], tuple(r["faces"])) for r in json.loads(recorded)]
    faces_of = {}
    for face, row in zip(cube.faces(dim), face_rows):
        physical = int(row.split()[8])  # tag, 6 box values, number of physical tags, the tag
        faces_of.setdefault(groups[(dim - 1, physical)], []).append(face.name)
    return [Patch(name, types.get(name, "patch"), tuple(faces)) for name, faces in faces_of.items()]
