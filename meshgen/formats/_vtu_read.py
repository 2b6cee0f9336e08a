""".vtu files read by meshgen's own decoder for ``meshgen evaluate`` (``read_cells``).

meshio reads a .vtu by decoding every array on one thread: 1.2 s of a 100^3 mesh meshgen wrote
(its seven quality arrays included), most of ``meshgen evaluate``'s time on such a file. The
evaluation needs the points, the cells and at most the cell data ``block``: this reader decodes
only those, with the .vts reader's decoder (``_vts.decode_array``: inline base64 or raw appended,
zlib blocks inflated on all cores, each array's declared size checked against the piece's counts
before anything is inflated), and gives the ``meshio.Mesh`` that meshio would give of the same
file with the other arrays left out. Only files of one piece and one cell kind, hexahedra (VTK
type 12) or quadrilaterals (9), in order (offsets 8, 16, ... or 4, 8, ...); ``None`` for any
other .vtu, which meshio reads.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from meshgen.errors import FormatError, MeshgenError
from meshgen.formats._vts import decode_array, parse_xml, writable
from meshgen.formats._vtu import cpu_count
from meshgen.run.limits import READ_BYTES_PER_NODE, check_memory

__all__ = ["CELL_KINDS", "read_cells"]

CELL_KINDS = {12: ("hexahedron", 8), 9: ("quad", 4)}  # VTK cell type -> (meshio's name, corners)


def read_cells(path, cell_arrays=None):
    """The .vtu file ``path`` as a ``meshio.Mesh`` (points (N, 3) float64, one block of cells,
    the cell arrays named in ``cell_arrays`` (None: all), meshgen's field data), or None for a
    file this reader leaves to meshio (module text). FormatError for a file that does not hold
    what it declares."""
    import meshio

    root, appended = parse_xml(path, "UnstructuredGrid")
    grid = root.find("UnstructuredGrid")
    pieces = grid.findall("Piece") if grid is not None else []
    if len(pieces) != 1:
        return None
    piece = pieces[0]
    try:
        n_points, n_cells = int(piece.get("NumberOfPoints")), int(piece.get("NumberOfCells"))
    except (TypeError, ValueError):
        raise FormatError(f"{path}: the piece does not say how many points and cells it has") from None
    cells = {a.get("Name"): a for a in piece.findall("Cells/DataArray")}
    points = piece.find("Points/DataArray")
    if n_cells < 1 or points is None or set(cells) != {"connectivity", "offsets", "types"}:
        return None
    try:
        check_memory(n_points * READ_BYTES_PER_NODE, f"{path}: reading its {n_points} points")
    except MeshgenError as exc:
        raise FormatError(str(exc)) from None

    with ThreadPoolExecutor(max_workers=cpu_count(), thread_name_prefix="meshgen-vtu") as pool:

        def decode(element, count, name):
            return decode_array(element, root, appended, count, f"{path}: the {name} array", pool)

        types = decode(cells["types"], n_cells, "types")
        kind = CELL_KINDS.get(int(types[0]))
        if kind is None or np.any(types != types[0]):
            return None
        name, corners = kind
        offsets = decode(cells["offsets"], n_cells, "offsets")
        if not np.array_equal(offsets, np.arange(corners, corners * n_cells + 1, corners)):
            return None
        connectivity = decode(cells["connectivity"], corners * n_cells, "connectivity")
        connectivity = writable(connectivity.astype(np.int64, copy=False).reshape(n_cells, corners))
        coordinates = writable(decode(points, 3 * n_points, "points").astype(float, copy=False).reshape(n_points, 3))
        cell_data = {}
        for array in piece.findall("CellData/DataArray"):
            if cell_arrays is None or array.get("Name") in cell_arrays:
                components = int(array.get("NumberOfComponents", 1))
                values = decode(array, components * n_cells, f"cell data {array.get('Name')!r}")
                cell_data[array.get("Name")] = [writable(values.reshape(n_cells, components) if components > 1 else values)]
    field_data = {a.get("Name"): decode_array(a, root, appended).copy() for a in grid.findall("FieldData/DataArray")}
    return meshio.Mesh(coordinates, [(name, connectivity)], cell_data=cell_data, field_data=field_data)
