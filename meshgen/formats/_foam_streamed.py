"""An OpenFOAM case of a mesh larger than memory: the polyMesh of ``meshgen.formats._openfoam``,
byte for byte, written slab by slab from a node file (``meshgen.formats.streamed.NodeFile``).

OpenFOAM wants the internal faces in upper-triangular order (by owner, then neighbour) and then
the boundary faces patch by patch. With cells numbered in C order (i slowest), the internal faces
owned by the cells of an i-slab [i0, i1) form one contiguous run of that order: each cell's faces
go to its k+1, j+1 and i+1 neighbours, whose numbers increase in that order, and every owner of
the run is in the slab. So ``faces``, ``owner`` and ``neighbour`` are written slab after slab
(``internal_faces`` on the slab's nodes i0 .. i1+1, its last cell plane's i+1 faces included, the
rows of the cells past the slab dropped), then the boundary faces, whose count and offsets are
known in advance from the grid's shape alone; ``points`` are C order, i-slabs of the node file.
A 2D mesh is extruded slab by slab with the thickness of the whole mesh's area (one reading pass).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from meshgen.formats._foam_topology import boundary_owner, internal_faces, patch_entries, poly_mesh_note
from meshgen.formats._openfoam import extrude, extrusion_thickness, foam_header, signed_area, write_boundary, write_case
from meshgen.formats._structured import boundary_elements, node_labels
from meshgen.formats.streamed import NodeFile, list_end, list_start, list_values, map_orientation

__all__ = ["write_streamed"]

LOCATION = "constant/polyMesh"


def write_streamed(case, nodes: NodeFile, metadata: dict, patches, binary: bool = True) -> None:
    """Write the case of the mesh in ``nodes`` as ``meshgen.formats._openfoam.write`` would from
    the whole node array (the same files), slab by slab."""
    write_case(
        case, nodes.node_shape, metadata, patches, lambda folder, all_patches: _poly_mesh(folder, nodes, all_patches, binary)
    )


def _poly_mesh(folder: Path, nodes: NodeFile, patches, binary: bool) -> None:
    thickness = None
    if nodes.dim == 2:
        area = sum(signed_area(nodes.read(0, part, overlap=1)) for part in nodes.slabs(0) if part.start < nodes.node_shape[0] - 1)
        thickness = extrusion_thickness(area, (nodes.node_shape[0] - 1) * (nodes.node_shape[1] - 1))
    node_shape = tuple(nodes.node_shape) + ((2,) if nodes.dim == 2 else ())
    cell_shape = tuple(n - 1 for n in node_shape)
    positive = map_orientation(nodes) > 0
    fmt = "binary" if binary else "ascii"

    with open(folder / "points", "wb") as file:
        file.write(foam_header("vectorField", LOCATION, "points", fmt).encode())
        list_start(file, int(np.prod(node_shape)), binary)
        for part in nodes.slabs(0):
            slab = nodes.read(0, part)
            slab = extrude(slab, thickness) if thickness is not None else slab
            list_values(file, slab.reshape(-1, 3), binary, "({} {} {})")
        list_end(file)

    entries = patch_entries(node_shape, patches)
    internal = entries[0][3]
    faces = entries[-1][3] + entries[-1][2]
    note = poly_mesh_note(node_shape)
    with open(folder / "faces", "wb") as face_file, open(folder / "owner", "wb") as owner_file:
        with open(folder / "neighbour", "wb") as neighbour_file:
            if binary:
                face_file.write(foam_header("faceCompactList", LOCATION, "faces", fmt).encode())
                list_start(face_file, faces + 1, True)
                for first in range(0, faces + 1, 1 << 20):
                    list_values(face_file, np.arange(4 * first, 4 * min(first + (1 << 20), faces + 1), 4, dtype=np.int32), True)
                list_end(face_file)
                list_start(face_file, 4 * faces, True)
            else:
                face_file.write(foam_header("faceList", LOCATION, "faces", fmt).encode())
                list_start(face_file, faces, False)
            for name, file, count in (("owner", owner_file, faces), ("neighbour", neighbour_file, internal)):
                file.write(foam_header("labelList", LOCATION, name, fmt, note).encode())
                list_start(file, count, binary)
            face_row = "4({} {} {} {})"
            for part in _cell_slabs(nodes, cell_shape):
                # The slab's nodes and one more cell plane: the i+1 faces of its last cells and their neighbours.
                point_ids = node_labels(
                    node_shape, (slice(part.start, min(part.stop + 2, node_shape[0])), slice(None), slice(None))
                )
                cell_ids = node_labels(
                    cell_shape, (slice(part.start, min(part.stop + 1, cell_shape[0])), slice(None), slice(None))
                )
                face_nodes, owner, neighbour = internal_faces(point_ids.astype(np.int32), cell_ids.astype(np.int32), positive)
                mine = np.searchsorted(owner, part.stop * cell_shape[1] * cell_shape[2])  # owners in the slab
                list_values(face_file, face_nodes[:mine].reshape(-1) if binary else face_nodes[:mine], binary, face_row)
                list_values(owner_file, owner[:mine], binary)
                list_values(neighbour_file, neighbour[:mine], binary)
            for patch in patches:
                for face_name in patch.faces:
                    elements = boundary_elements(node_shape, face_name, positive).astype(np.int32)
                    list_values(face_file, elements.reshape(-1) if binary else elements, binary, face_row)
                    list_values(owner_file, boundary_owner(cell_shape, face_name), binary)
            for file in (face_file, owner_file, neighbour_file):
                list_end(file)
    write_boundary(folder, entries)


def _cell_slabs(nodes: NodeFile, cell_shape) -> list[slice]:
    """Slabs of cell planes along i with about ``nodes.block_nodes`` cells each."""
    plane = int(np.prod(cell_shape[1:]))
    step = max(1, nodes.block_nodes // max(1, plane))
    return [slice(s, min(s + step, cell_shape[0])) for s in range(0, cell_shape[0], step)]
