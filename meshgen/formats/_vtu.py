"""VTK XML unstructured grid (.vtu) writer: hexahedron (quad) cells, per-cell arrays and meshgen's
metadata, zlib-compressed in blocks on all cores.

meshio's writer deflates at zlib's default level (6) on one thread: about 3 s of a 1e6-cell mesh
with its seven quality arrays. Here each array is cut into blocks of ``BLOCK_BYTES`` that a
thread pool deflates as soon as the array exists, while the calling thread builds the next array
or encodes and writes the finished ones. The deflate is ISA-L's (``isal.isal_zlib``, which
releases the GIL): its streams are ordinary zlib streams that VTK's ``vtkZLibDataCompressor`` and
meshio inflate, made at about a sixth of zlib's CPU time and 3% larger (level 1 of each;
design notes §21, benchmarks/formats.py). Reading stays with meshio (``read``), but for
``meshgen evaluate``, whose reader of the points and cells alone is ``_vtu_read``.

The file, VTK's XML format version 1.0 as VTK writes it in its "binary" data mode::

    <VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian"
             header_type="UInt64" compressor="vtkZLibDataCompressor">
      <UnstructuredGrid>
        <FieldData>   UInt8 "meshgen": the metadata's JSON bytes (only with metadata)
        <Piece NumberOfPoints=N NumberOfCells=C>
          <Points>    Float64, 3 components (2D meshes: z = 0)
          <Cells>     connectivity Int64 (C x 8 or 4 node indices, VTK corner order),
                      offsets Int64 (8, 16, ...), types UInt8 (12 hexahedron, 9 quad)
          <CellData>  one Float64 array per name, cells in C order (i, j[, k])
      </UnstructuredGrid>
    </VTKFile>

Every ``DataArray`` is ``format="binary"``: its text is the base64 of its compression header,
then (encoded separately, as VTK's readers expect) the base64 of its zlib streams one after the
other. The header is UInt64 little-endian: [number of blocks, block size, size of the last block
if shorter than a block else 0, compressed size of each block]; each block is ``BLOCK_BYTES`` of
the array's bytes, the last one possibly fewer.

Inline base64 rather than raw appended data: as fast to write (encoding is about 0.1 s of 80 MB)
and meshio reads it directly, whereas it reads raw appended data by inflating and re-encoding
all of it first (0.6 s against 4.7 s at 1e6 hexahedra); the price is a file 4/3 larger.
"""

from __future__ import annotations

import base64
import functools
import itertools
import os
import zlib
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from isal import isal_zlib

from meshgen.formats._xml import quoteattr
from meshgen.formats.metadata import METADATA_KEY, metadata_json
from meshgen.geometry.grid import HEX_CORNERS, QUAD_CORNERS, flat_points

__all__ = [
    "BLOCK_BYTES",
    "FILE_HEAD",
    "HEADER_TYPE",
    "LEVEL",
    "SMALL_BLOCK",
    "VTK_TYPES",
    "compress_block",
    "compress_blocks",
    "compression_header",
    "cpu_count",
    "read",
    "write",
    "write_cells",
]

# ISA-L's level 1 (of 0-3): on the 1e6-hexahedron mesh with its seven quality arrays 3% larger
# than zlib's level 1 at a sixth of its CPU time; level 0 is a third larger and hardly faster, level
# 2 the same size at a quarter more CPU (benchmarks/formats.py, design notes §21).
LEVEL = 1
BLOCK_BYTES = 1 << 20  # uncompressed bytes per block: enough blocks to share out, few Python calls
SMALL_BLOCK = 1 << 16  # below: zlib, whose output is a function of its input (``compress_block``)
ZLIB_LEVEL = 1
HEADER_TYPE = np.dtype("<u8")
VTK_TYPES = {np.dtype("<f8"): "Float64", np.dtype("<i8"): "Int64", np.dtype("u1"): "UInt8"}
VTK_HEXAHEDRON, VTK_QUAD = 12, 9
FILE_HEAD = (
    b'<?xml version="1.0"?>\n'
    b'<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64" '
    b'compressor="vtkZLibDataCompressor">\n<UnstructuredGrid>\n'
)


def write(path, X, cell_data, metadata, level=LEVEL, block_bytes=BLOCK_BYTES):
    """Write node array ``X`` (n1+1, n2+1[, n3+1], dim) as a compressed .vtu, with ``cell_data``
    (name -> (cells,) float64 array in C order of the cells, or a callable returning that mapping:
    called in this thread once the metadata, points and cells are handed to the compressing
    threads, so that computing the cell data overlaps compressing them; the file is the same
    either way) and ``metadata`` (JSON-serialisable dict; none stored when empty). ``level``: see
    ``compress_block``;
    ``block_bytes``: uncompressed bytes per block, a multiple of 8 (meshio decodes each block
    into whole values)."""
    node_shape = X.shape[:-1]
    write_cells(
        path, lambda: flat_points(X), lambda: _connectivity(node_shape), len(node_shape), cell_data, metadata, level, block_bytes
    )


def write_cells(path, points, cells, dim: int, cell_data, metadata, level=LEVEL, block_bytes=BLOCK_BYTES):
    """Write an unstructured mesh as :func:`write` writes a node array: ``points`` (N, 3) float64
    and ``cells`` (C, 8 or 4) int64 in VTK corner order (each an array, or a callable returning
    it, called in that order once the arrays before it are handed to the compressing threads),
    hexahedra (``dim`` 3) or quads (2); ``cell_data`` and ``metadata`` as :func:`write` takes them
    (a block set's merged mesh: ``meshgen.formats.multiblock``)."""
    compress = functools.partial(compress_block, level=level)
    pool = ThreadPoolExecutor(max_workers=cpu_count())
    arrays = []  # (element, name, further attributes, type, bytes, compressed blocks) in file order

    def add(element, name, more, values):
        # Each array is handed to the pool as soon as it exists: the points compress while the
        # cells are built.
        values = _little_endian(values)
        arrays.append((element, name, more, values.dtype, values.nbytes, compress_blocks(pool, values, compress, block_bytes)))

    try:
        if metadata:
            codes = np.frombuffer(metadata_json(metadata).encode("ascii"), dtype=np.uint8)
            add("FieldData", METADATA_KEY, {"NumberOfTuples": codes.size}, codes)
        points = points() if callable(points) else points
        add("Points", "Points", {"NumberOfComponents": 3}, points)
        connectivity = cells() if callable(cells) else cells
        cell_count, corner_count = connectivity.shape
        add("Cells", "connectivity", {}, connectivity)
        add("Cells", "offsets", {}, np.arange(1, cell_count + 1, dtype=np.int64) * corner_count)
        add("Cells", "types", {}, np.full(cell_count, VTK_HEXAHEDRON if dim == 3 else VTK_QUAD, dtype=np.uint8))
        if callable(cell_data):
            cell_data = cell_data()
        for name, values in (cell_data or {}).items():
            add("CellData", name, {}, values)

        with open(path, "wb") as file:
            file.write(FILE_HEAD)
            for element, group in itertools.groupby(arrays, key=lambda array: array[0]):
                if element == "Points":
                    file.write(f'<Piece NumberOfPoints="{len(points)}" NumberOfCells="{cell_count}">\n'.encode())
                file.write(f"<{element}>\n".encode())
                for _, name, more, dtype, nbytes, blocks in group:
                    streams = [block.result() for block in blocks]
                    _write_data_array(file, name, more, dtype, compression_header(nbytes, block_bytes, streams), streams)
                file.write(f"</{element}>\n".encode())
            file.write(b"</Piece>\n</UnstructuredGrid>\n</VTKFile>\n")
    finally:
        pool.shutdown(cancel_futures=True)  # after a failure (or Ctrl-C), drop the blocks not yet started


def compress_block(block, level: int = LEVEL) -> bytes:
    """One zlib stream of ``block`` (bytes-like), deflated by ISA-L at ``level`` (0-3), or by zlib
    below ``SMALL_BLOCK`` bytes; any zlib reader inflates it.

    Small blocks (metadata, patch lists, the arrays of small meshes) go to zlib: ISA-L encodes
    the same small input differently from one process state to another (measured: a 241-byte
    patch list deflated to 112 or 114 bytes, both valid, after other work in the process), and a
    mesh must be written to the same bytes every time; zlib's output depends on its input alone.
    Where the time is, in blocks of ``BLOCK_BYTES``, ISA-L keeps its speed."""
    if memoryview(block).nbytes < SMALL_BLOCK:
        return zlib.compress(block, ZLIB_LEVEL)
    return isal_zlib.compress(block, level)


def compress_blocks(pool, array: np.ndarray, compress=compress_block, block_bytes: int = BLOCK_BYTES) -> list:
    """Futures of ``compress(block)`` for the blocks of ``block_bytes`` of C-contiguous ``array``."""
    view = memoryview(array).cast("B")
    return [pool.submit(compress, view[start : start + block_bytes]) for start in range(0, len(view), block_bytes)]


def compression_header(nbytes: int, block_bytes: int, streams) -> bytes:
    """VTK's header of a compressed array of ``nbytes`` bytes: [number of blocks, block size, size
    of the last block if shorter else 0, compressed size of each block], ``HEADER_TYPE``."""
    return np.array([len(streams), block_bytes, nbytes % block_bytes, *map(len, streams)], dtype=HEADER_TYPE).tobytes()


def _connectivity(node_shape) -> np.ndarray:
    """The cells of ``meshgen.geometry.grid.cell_connectivity``, (cells, 8 or 4) int64, as one broadcast sum:
    each cell's first node index plus the flat offsets of its VTK corners (3-4x faster there)."""
    node_shape = tuple(int(n) for n in node_shape)
    corners = HEX_CORNERS if len(node_shape) == 3 else QUAD_CORNERS
    strides = np.cumprod((1,) + node_shape[:0:-1])[::-1]  # flat-index step along each axis
    first_node = np.zeros((), dtype=np.int64)
    for axis, n in enumerate(node_shape):
        first_node = np.add.outer(first_node, np.arange(n - 1, dtype=np.int64) * strides[axis])
    return first_node.reshape(-1, 1) + (corners @ strides).astype(np.int64)


def _little_endian(values: np.ndarray) -> np.ndarray:
    """``values`` C-contiguous in the little-endian type of its kind: float64, int64 or uint8."""
    dtype = {"f": "<f8", "i": "<i8", "u": "u1"}[values.dtype.kind]
    return np.ascontiguousarray(values, dtype=dtype)


def _write_data_array(file, name: str, more: dict, dtype, header: bytes, streams: list) -> None:
    """One DataArray element: the base64 of the header, then that of the streams joined, encoded
    stream by stream (base64 of a whole number of 3-byte groups needs no padding, so the pieces
    join to the base64 of the whole without the whole ever being in memory)."""
    attributes = "".join(f' {key}="{value}"' for key, value in more.items())
    file.write(f'<DataArray type="{VTK_TYPES[dtype]}" Name={quoteattr(name)}{attributes} format="binary">\n'.encode())
    file.write(base64.b64encode(header))
    pending = b""
    for stream in streams:
        data = pending + stream
        whole = len(data) - len(data) % 3
        file.write(base64.b64encode(memoryview(data)[:whole]))
        pending = data[whole:]
    file.write(base64.b64encode(pending))
    file.write(b"\n</DataArray>\n")


def cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def read(path):
    """Read a .vtu (ours or any other) with meshio."""
    import meshio

    return meshio.read(path, file_format="vtu")
