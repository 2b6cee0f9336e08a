"""SU2 native mesh (.su2, ASCII): the cells, the points and one marker per patch.

    % meshgen: {metadata JSON}          (a comment line; only with metadata)
    % meshgen_patches: [{"name", "type", "faces"}]
    NDIME= 3                            (2D: 2, points x y)
    NELEM= C
    12 n0 .. n7 c                       hexahedron (2D: 9 quadrilateral), VTK corner order, then its index
    NPOIN= N
    x y z i                             the nodes in C order of the node array, then the index
    NMARK= P
    MARKER_TAG= inlet                   one block per patch, its boundary elements with outward
    MARKER_ELEMS= m                     normals (2D: 3 line segments, domain on their left)
    9 a b c d

Node indices are 0-based. SU2 takes the boundary conditions from its configuration file by
marker name (MARKER_EULER= ( wall ), ...): the patch types have no place in the mesh and are kept
in the comment only.
"""

from __future__ import annotations

import contextlib
import io
import json
import re

import numpy as np

from meshgen.errors import FormatError
from meshgen.formats._structured import boundary_elements, orientation, write_rows
from meshgen.formats.metadata import METADATA_KEY, metadata_json
from meshgen.formats.streamed import cell_slabs, cells_of_slab, map_orientation
from meshgen.geometry.grid import cell_connectivity, flat_points
from meshgen.geometry.patches import as_records, from_records

__all__ = ["MARKER_NAME", "check_patch_name", "read", "read_patches", "write", "write_elements", "write_parts", "write_streamed"]

SU2_HEXAHEDRON, SU2_QUADRILATERAL, SU2_LINE = 12, 9, 3
MARKER_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.+-]*")


def check_patch_name(name: str) -> None:
    if not MARKER_NAME.fullmatch(name):
        raise FormatError(f"patch name '{name}' cannot be an SU2 marker (a letter or _ first, then letters, digits, _ . + -)")


def write(path, X, cell_data, metadata, patches):
    """Write node array ``X`` with one marker per patch; ``cell_data`` has no place in .su2."""
    node_shape = X.shape[:-1]
    dim = len(node_shape)
    positive = orientation(X) > 0
    markers = [
        (patch.name, np.concatenate([boundary_elements(node_shape, face, positive) for face in patch.faces])) for patch in patches
    ]
    write_elements(path, X.reshape(-1, dim), cell_connectivity(node_shape), markers, metadata, as_records(patches))


def write_elements(path, points, cells, markers, metadata, records) -> None:
    """Write an unstructured mesh: ``points`` (N, dim), ``cells`` (M, 8) hexahedra or (M, 4)
    quads (VTK corner order, 0-based), ``markers`` [(name, elements)] with elements (F, 4) quads
    (outward normals) or (E, 2) segments (domain on their left); ``records``: the patches'
    records for the ``meshgen_patches`` comment."""
    write_parts(path, points.shape[1], len(points), [points], len(cells), [cells], markers, metadata, records)


def write_parts(path, dim: int, point_count: int, point_parts, cell_count: int, cell_parts, markers, metadata, records) -> None:
    """``write_elements`` with the points and cells given in consecutive parts (iterables of
    (n, dim) and (m, corners) arrays): a mesh larger than memory is written part by part."""
    with open(path, "wb") as file:
        if metadata:
            file.write(f"% meshgen: {metadata_json(metadata)}\n".encode())
        file.write(f"% meshgen_patches: {json.dumps(records)}\n".encode())
        file.write(f"NDIME= {dim}\nNELEM= {cell_count}\n".encode())
        kind = SU2_HEXAHEDRON if dim == 3 else SU2_QUADRILATERAL
        first = 0
        for cells in cell_parts:
            rows = np.column_stack([np.full(len(cells), kind), cells, np.arange(first, first + len(cells))])
            write_rows(file, rows, " ".join(["{}"] * rows.shape[1]))
            first += len(cells)
        file.write(f"NPOIN= {point_count}\n".encode())
        for points in point_parts:
            write_rows(file, points, " ".join(["{}"] * dim))
        file.write(f"NMARK= {len(markers)}\n".encode())
        for name, elements in markers:
            file.write(f"MARKER_TAG= {name}\nMARKER_ELEMS= {len(elements)}\n".encode())
            kind = SU2_QUADRILATERAL if dim == 3 else SU2_LINE
            write_rows(
                file, np.column_stack([np.full(len(elements), kind), elements]), " ".join(["{}"] * (elements.shape[1] + 1))
            )


def write_streamed(path, nodes, metadata, patches) -> None:
    """``write`` of the mesh in ``nodes`` (``meshgen.formats.streamed.NodeFile``), slab by slab:
    the orientation first (a reading pass), then cells and points by i-slabs."""
    node_shape, dim = nodes.node_shape, nodes.dim
    positive = map_orientation(nodes) > 0
    markers = [
        (patch.name, np.concatenate([boundary_elements(node_shape, face, positive) for face in patch.faces])) for patch in patches
    ]
    point_parts = (nodes.read(0, part).reshape(-1, dim) for part in nodes.slabs(0))
    cell_parts = (cells_of_slab(node_shape, part) for part in cell_slabs(node_shape, nodes.block_nodes))
    cell_count = int(np.prod([n - 1 for n in node_shape]))
    write_parts(path, dim, int(np.prod(node_shape)), point_parts, cell_count, cell_parts, markers, metadata, as_records(patches))


def _comment(path, key: str) -> str | None:
    with open(path, "rb") as file:
        for line in file:
            if not line.startswith(b"%"):
                return None
            text = line[1:].decode("utf-8", "replace").strip()
            if text.startswith(f"{key}:"):
                return text[len(key) + 1 :].strip()
    return None


def read(path):
    """Read with meshio; a file meshgen wrote (it has the ``meshgen_patches`` comment) keeps only
    its cells (hexahedra or quads, not the markers' boundary elements) and gives its metadata
    back."""
    import meshio

    # meshio warns for every marker that its tags are strings: expected here, and not the user's concern.
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        mesh = meshio.read(path, file_format="su2")
    if _comment(path, "meshgen_patches") is None:  # a foreign file: as meshio reads it
        return mesh
    volume = "hexahedron" if any(block.type == "hexahedron" for block in mesh.cells) else "quad"
    blocks = [block for block in mesh.cells if block.type == volume]
    points = np.asarray(mesh.points, dtype=float)
    field_data = {}
    text = _comment(path, METADATA_KEY)
    if text:
        field_data[METADATA_KEY] = np.frombuffer(text.encode(), dtype=np.uint8).copy()
    return meshio.Mesh(flat_points(points), [(volume, np.concatenate([b.data for b in blocks]))], field_data=field_data)


def read_patches(path) -> list:
    """The markers of a .su2 file meshgen wrote, with the patch types of its comment line."""
    text = _comment(path, "meshgen_patches")
    if text is None:
        raise FormatError(f"{path}: no meshgen_patches comment (not written by meshgen)")
    patches = from_records(json.loads(text))
    with open(path, "rb") as file:
        markers = [m.decode() for m in re.findall(rb"^MARKER_TAG=\s*(\S+)", file.read(), re.M)]
    if markers != [p.name for p in patches]:
        raise FormatError(f"{path}: markers {markers} disagree with the recorded patches")
    return patches
