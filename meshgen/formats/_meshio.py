"""Legacy VTK (.vtk) and XDMF (.xdmf) through meshio: hexahedron (quad) cells, per-cell arrays,
and meshgen's metadata as JSON, where VTK, ParaView and meshio read it back; reading any format
meshio knows. (.vtu is written by meshgen's own writer, ``meshgen.formats._vtu``.)

meshio's vtk writer drops field data and its XDMF writer has no place for it, so the metadata is
added to the file meshio wrote (still the temporary file of the atomic write):

- .vtk (binary, DataFile Version 4.2): a ``FIELD FieldData 1`` block with the unsigned_char
  array "meshgen", after the cell types and before the cell data (which meshgen then appends
  itself, in meshio's layout): VTK reads it as dataset field data and meshio as ``field_data``.
  Version 4.2 rather than meshio's default 5.1: every VTK-based reader understands it (5.1 needs
  VTK 9 / ParaView 5.8), and VTK's and meshio's 5.1 readers share no byte-sized array type.
- .xdmf: ``<Information Name="meshgen" Value="{JSON}">``, first child of the Grid (XDMF's
  key/value form). Its text is the empty XML document ``<meshgen/>`` because meshio's XDMF
  reader parses the text of a Grid's Information as XML.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import numpy as np

from meshgen.errors import FormatError
from meshgen.formats._xml import escape
from meshgen.formats.metadata import METADATA_KEY, metadata_json
from meshgen.geometry.grid import cell_connectivity, flat_points

__all__ = ["HEADER_BYTES", "read", "write"]

# How far into a file meshio's header reaches: the insertion points lie before any array data.
HEADER_BYTES = 1 << 16


def _file_format(path) -> str:
    return {".vtk": "vtk", ".xdmf": "xdmf"}[path.suffix.lower()]


def write(path, X, cell_data, metadata):
    """Write node array ``X`` (n1+1, n2+1[, n3+1], dim) with meshio, plus ``cell_data`` (arrays
    in C order of the cells) and ``metadata`` (JSON-serialisable dict)."""
    import meshio

    cell_type = "hexahedron" if X.ndim == 4 else "quad"
    cells = [(cell_type, cell_connectivity(X.shape[:-1]))]
    cell_arrays = {name: np.asarray(values, dtype=float).reshape(-1) for name, values in cell_data.items()}
    text = metadata_json(metadata) if metadata else ""
    file_format = _file_format(path)
    if file_format == "vtk":
        # meshio writes points, cells and cell types; the metadata must come before the cell data.
        meshio.vtk.write(path, meshio.Mesh(flat_points(X), cells), fmt_version="4.2", binary=True)
        with open(path, "ab") as file:
            if text:
                file.write(_legacy_field(text))
            if cell_arrays:
                file.write(_legacy_cell_data(cell_arrays, len(cells[0][1])))
    else:
        mesh = meshio.Mesh(flat_points(X), cells, cell_data={name: [v] for name, v in cell_arrays.items()})
        # Inline XML keeps the mesh one self-contained file, so the atomic rename covers all of it.
        meshio.xdmf.write(path, mesh, data_format="XML")
        if text:
            _insert_after(path, rb"<Grid\b[^>]*>", _xdmf_information(text))


def read(path):
    """Read with meshio; for XDMF, also pick meshgen's metadata out of the Information element."""
    import meshio

    mesh = meshio.read(path)
    if path.suffix.lower() == ".xdmf" and METADATA_KEY not in mesh.field_data:
        text = _xdmf_metadata(path)
        if text is not None:
            mesh.field_data[METADATA_KEY] = np.frombuffer(text.encode(), dtype=np.uint8).copy()
    return mesh


def _legacy_field(text: str) -> bytes:
    """A dataset-level FIELD block with one unsigned_char array (binary legacy VTK)."""
    data = text.encode("ascii")
    return f"FIELD FieldData 1\n{METADATA_KEY} 1 {len(data)} unsigned_char\n".encode() + data + b"\n"


def _legacy_cell_data(cell_arrays: dict, cell_count: int) -> bytes:
    """CELL_DATA as meshio writes it: one FIELD of big-endian double arrays."""
    parts = [f"CELL_DATA {cell_count}\nFIELD FieldData {len(cell_arrays)}\n".encode()]
    for name, values in cell_arrays.items():
        if not name or any(c.isspace() for c in name):
            raise FormatError(f"cell data name '{name}' cannot be written to legacy VTK (empty or has spaces)")
        parts += [f"{name} 1 {values.size} double\n".encode(), values.astype(">f8").tobytes(), b"\n"]
    return b"".join(parts)


def _xdmf_information(text: str) -> bytes:
    value = escape(text, {'"': "&quot;"})
    return f'<Information Name="{METADATA_KEY}" Value="{value}">&lt;{METADATA_KEY}/&gt;</Information>'.encode("ascii")


def _insert_after(path, start_tag: bytes, insertion: bytes) -> None:
    """Insert ``insertion`` right after the first match of the regular expression ``start_tag``
    in the header of the file at ``path``."""
    with open(path, "r+b") as file:
        match = re.search(start_tag, file.read(HEADER_BYTES))
        if match is None:
            raise FormatError(f"no {start_tag.decode()} in the file meshio wrote, so no place for the metadata")
        position = match.end()
        file.seek(position)
        rest = file.read()
        file.seek(position)
        file.write(insertion)
        file.write(rest)


def _xdmf_metadata(path) -> str | None:
    """The Value of the first Information element named "meshgen", read without parsing the
    (possibly large) data that follows it."""
    for _, element in ET.iterparse(path, events=("start",)):
        if element.tag == "Information" and element.get("Name") == METADATA_KEY:
            return element.get("Value")
        if element.tag in ("Geometry", "Topology", "Attribute"):
            return None
    return None
