"""Plot3D grid files: the mesh as one block, whole (not planes), without iblank.

``.xyz``: binary, the variant structured CFD solvers (OVERFLOW, CFL3D, ...) and most grid tools
read by default: Fortran unformatted sequential records, each framed by its int32 byte count,
little-endian, multi-grid with one block, double precision::

    [4] nblocks = 1 [4]
    [4*dim] ni nj [nk] [4*dim]                                 (int32)
    [8*dim*N] x(i,j,k) ..., y(i,j,k) ..., [z(i,j,k) ...] [8*dim*N]   (float64, i fastest)

``.fmt``: the same multi-grid layout formatted (ASCII): "1", then the dimensions, then the
coordinates, x block first, one value per line with 17 significant digits (exact round trip).

2D meshes are Plot3D 2D files: two dimensions and x, y only (``dim`` = 2 above).

Reading them elsewhere:
- ParaView "PLOT3D Files" reader / VTK's vtkMultiBlockPLOT3DReader, ``.xyz``: AutoDetectFormat=1
  (ParaView's default), or explicitly BinaryFile=1, MultiGrid=1, HasByteCount=1, IBlanking=0,
  ByteOrder=LittleEndian, DoublePrecision=1, and TwoDimensionalGeometry=1 for a 2D mesh.
  ``.fmt``: auto-detection is for binary files only; set BinaryFile=0, MultiGrid=1,
  DoublePrecision=1 (else values are read as float32) and TwoDimensionalGeometry as above.
- CGNS tools: ``plot3d_to_cgns -u -d mesh.xyz mesh.cgns`` (``-f -d`` for ``.fmt``).

Plot3D has no place for cell data or metadata: the writer leaves them out, the reader returns
none. ``read`` also accepts single-grid files, big-endian files, single precision and iblank
(ignored), but only one block.
"""

from __future__ import annotations

import numpy as np

from meshgen.errors import FormatError
from meshgen.geometry.grid import cell_connectivity, flat_points

__all__ = ["RECORD_LIMIT", "check_node_shape", "read", "write", "write_streamed"]

RECORD_LIMIT = 2**31 - 1  # bytes in one Fortran record: its byte count is an int32


def write(path, X, cell_data, metadata):
    """Write node array ``X`` (n1+1, n2+1[, n3+1], dim) as a one-block whole grid; binary for
    ``.xyz``, formatted for ``.fmt``. ``cell_data`` and ``metadata`` have no place in Plot3D."""
    node_shape = X.shape[:-1]
    check_node_shape(node_shape, path)
    dims = np.array([1, *node_shape], dtype="<i4")
    # Coordinate blocks x, y[, z], each in Fortran order (i fastest): the transpose of C order.
    coordinates = np.ascontiguousarray(np.moveaxis(X, -1, 0).transpose(0, *range(X.ndim - 1, 0, -1)), dtype="<f8")
    if _is_formatted(path):
        with open(path, "w") as file:
            file.write(f"{dims[0]}\n{' '.join(map(str, dims[1:]))}\n")
            file.write("\n".join(map(repr, coordinates.reshape(-1).tolist())))
            file.write("\n")
    else:
        with open(path, "wb") as file:
            _write_record(file, dims[:1])
            _write_record(file, dims[1:])
            _write_record(file, coordinates)


def check_node_shape(node_shape, path) -> None:
    """FormatError when the coordinates of a mesh of ``node_shape`` nodes overflow the 32-bit byte
    count of a binary file's one record (formatted files have no such limit)."""
    nbytes = 8 * len(node_shape) * int(np.prod(node_shape))
    if not _is_formatted(path) and nbytes > RECORD_LIMIT:
        raise FormatError(
            f"Plot3D: the coordinates ({nbytes} bytes) overflow a binary record's 32-bit byte count; the formatted .fmt has no limit"
        )


def write_streamed(path, nodes, metadata, patches=()) -> None:
    """``write`` of the mesh in ``nodes`` (``meshgen.formats.streamed.NodeFile``): each coordinate
    block by slabs of the last axis (k), which are contiguous runs of Fortran order; one reading
    pass per coordinate."""
    node_shape, dim = tuple(nodes.node_shape), nodes.dim
    dims = np.array([1, *node_shape], dtype="<i4")
    order = tuple(range(dim - 1, -1, -1))  # Fortran order: the transpose of C order

    def component_parts():
        for axis in range(dim):
            for part in nodes.slabs(dim - 1):
                yield np.ascontiguousarray(np.transpose(nodes.read(dim - 1, part)[..., axis], order), dtype="<f8").reshape(-1)

    if _is_formatted(path):
        with open(path, "w") as file:
            file.write(f"{dims[0]}\n{' '.join(map(str, dims[1:]))}\n")
            for values in component_parts():
                file.write("\n".join(map(repr, values.tolist())))
                file.write("\n")
        return
    check_node_shape(node_shape, path)
    nbytes = 8 * dim * int(np.prod(node_shape))
    marker = np.array([nbytes], dtype="<i4").tobytes()
    with open(path, "wb") as file:
        _write_record(file, dims[:1])
        _write_record(file, dims[1:])
        file.write(marker)
        for values in component_parts():
            values.tofile(file)
        file.write(marker)


def read(path):
    """Read a one-block Plot3D grid (binary ``.xyz``, formatted ``.fmt``) as a ``meshio.Mesh``:
    points in the C order of the nodes padded to 3 columns, hexahedron (quad) cells."""
    import meshio

    node_shape, coordinates = (_read_formatted if _is_formatted(path) else _read_binary)(path)
    dim = len(node_shape)
    fortran_shape = (dim, *node_shape[::-1])
    X = np.moveaxis(coordinates.reshape(fortran_shape).transpose(0, *range(dim, 0, -1)), 0, -1)
    cell_type = "hexahedron" if dim == 3 else "quad"
    return meshio.Mesh(flat_points(X), [(cell_type, cell_connectivity(node_shape))])


def _is_formatted(path) -> bool:
    return str(path).lower().endswith(".fmt")


def _write_record(file, values: np.ndarray) -> None:
    """One Fortran unformatted sequential record: int32 byte count, the bytes, the count again."""
    marker = np.array([values.nbytes], dtype="<i4").tobytes()
    file.write(marker)
    values.tofile(file)
    file.write(marker)


def _records(data: bytes, byte_order: str) -> list[bytes]:
    records, position = [], 0
    while position < len(data):
        if position + 4 > len(data):
            raise FormatError("truncated Fortran record marker")
        (length,) = np.frombuffer(data, dtype=f"{byte_order}i4", count=1, offset=position)
        end = position + 4 + int(length)
        if length < 0 or end + 4 > len(data) or data[end : end + 4] != data[position : position + 4]:
            raise FormatError("not a Fortran unformatted file (record markers do not match)")
        records.append(data[position + 4 : end])
        position = end + 4
    return records


def _read_binary(path):
    data = open(path, "rb").read()
    if len(data) < 4:
        raise FormatError(f"{path} is not a Plot3D file (too short)")
    # The first record is 4 bytes (multi-grid: nblocks) or 8 or 12 (single grid: dimensions).
    byte_order = "<" if int(np.frombuffer(data, "<i4", 1)[0]) in (4, 8, 12) else ">"
    records = _records(data, byte_order)
    integers = [np.frombuffer(record, f"{byte_order}i4") for record in records[:2]]
    if len(records) == 3 and integers[0].size == 1:
        if integers[0][0] != 1:
            raise FormatError(f"{path} has {integers[0][0]} blocks; meshgen reads one-block Plot3D files")
        dims, coordinate_record = integers[1], records[2]
    elif len(records) == 2:
        dims, coordinate_record = integers[0], records[1]
    else:
        raise FormatError(f"{path}: {len(records)} records, expected a one-block Plot3D grid (2 or 3 records)")
    node_shape = tuple(int(n) for n in dims)
    if len(node_shape) not in (2, 3) or min(node_shape) < 1:
        raise FormatError(f"{path}: bad Plot3D dimensions {list(dims)}")
    nodes = int(np.prod(node_shape))
    dim = len(node_shape)
    # Coordinates in float64 or float32, optionally followed by int32 iblank (ignored).
    for size, with_iblank in ((8, False), (4, False), (8, True), (4, True)):
        if len(coordinate_record) == nodes * (dim * size + 4 * with_iblank):
            coordinates = np.frombuffer(coordinate_record, f"{byte_order}f{size}", count=dim * nodes)
            return node_shape, coordinates.astype(float)
    raise FormatError(f"{path}: coordinate record of {len(coordinate_record)} bytes does not fit {node_shape} nodes")


def _read_formatted(path):
    try:
        numbers = np.array(open(path).read().split(), dtype=float)
    except ValueError as exc:
        raise FormatError(f"{path} is not a formatted Plot3D file: {exc}") from exc
    # Multi-grid (leading nblocks = 1) or single grid; 2D or 3D; with or without iblank: the one
    # reading whose dimensions account for exactly all the numbers.
    for header in (1, 0):
        if header and (numbers.size == 0 or numbers[0] != 1):
            continue
        for dim in (3, 2):
            dims = numbers[header : header + dim]
            if dims.size < dim or np.any(dims < 1) or np.any(dims != np.round(dims)):
                continue
            nodes = int(np.prod(dims))
            for with_iblank in (False, True):
                if numbers.size == header + dim + nodes * (dim + with_iblank):
                    coordinates = numbers[header + dim : header + dim + dim * nodes]
                    return tuple(int(n) for n in dims), coordinates
    raise FormatError(f"{path}: the numbers do not form a one-block Plot3D grid")
