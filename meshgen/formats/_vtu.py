"""VTK XML unstructured grid (.vtu) writer: hexahedron (quad) cells, per-cell arrays and meshgen's
metadata, zlib-compressed in blocks on all cores.

meshio's writer compresses at zlib's default level (6) on one thread: about 3 s of a 1e6-cell mesh
with its seven quality arrays. Here the arrays are cut into blocks of ``BLOCK_BYTES`` that a
thread pool compresses at ``LEVEL`` (zlib releases the GIL) while the calling thread encodes and
writes the arrays already done, and the cells are built in one broadcast sum. Reading stays with
meshio (``read``).

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

Inline base64 rather than raw appended data: as fast to write (the encoding is ~5% of the time)
and meshio reads it directly, whereas it reads raw appended data by decompressing and
re-encoding it all first (0.6 s against 4.7 s at 1e6 hexahedra); the price is a file 4/3 larger.
"""

from __future__ import annotations

import base64
import functools
import os
import zlib
from concurrent.futures import ThreadPoolExecutor
from xml.sax.saxutils import quoteattr

import numpy as np

from meshgen.grid import HEX_CORNERS, QUAD_CORNERS, flat_points

# zlib level 1: at 1e6 hexahedra with seven quality arrays 3% larger than level 3 and 13% larger
# than level 6 (meshio's), at 3/4 and 1/3 of their compression time (benchmarks/formats.py).
LEVEL = 1
# Where a block's first PROBE_BYTES shrink to more than RLE_ABOVE of their size at LEVEL, string
# matches find little (the low bits of computed float64 values): the block is then deflated with
# run-length matches only (Z_RLE), 1.6-2.3x faster there and 5-10% larger.
PROBE_BYTES = 1 << 16
RLE_ABOVE = 0.8
BLOCK_BYTES = 1 << 20  # uncompressed bytes per block: enough blocks to share out, few Python calls
HEADER_TYPE = np.dtype("<u8")
VTK_TYPES = {np.dtype("<f8"): "Float64", np.dtype("<i8"): "Int64", np.dtype("u1"): "UInt8"}
VTK_HEXAHEDRON, VTK_QUAD = 12, 9
FILE_HEAD = (
    b'<?xml version="1.0"?>\n'
    b'<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64" '
    b'compressor="vtkZLibDataCompressor">\n<UnstructuredGrid>\n'
)


def write(path, X, cell_data, metadata, level=LEVEL, rle_above=RLE_ABOVE, block_bytes=BLOCK_BYTES):
    """Write node array ``X`` (n1+1, n2+1[, n3+1], dim) as a compressed .vtu, with ``cell_data``
    (name -> (cells,) float64 array in C order of the cells) and ``metadata`` (JSON-serialisable
    dict; none stored when empty). ``level``, ``rle_above``: see ``compress_block``;
    ``block_bytes``: uncompressed bytes per block, a multiple of 8 (meshio decodes each block
    into whole values)."""
    from meshgen.formats import METADATA_KEY, metadata_json

    node_shape = X.shape[:-1]
    connectivity = _connectivity(node_shape)
    cell_count, corner_count = connectivity.shape
    field_arrays = []
    if metadata:
        codes = np.frombuffer(metadata_json(metadata).encode("ascii"), dtype=np.uint8)
        field_arrays.append((METADATA_KEY, {"NumberOfTuples": codes.size}, codes))
    # (element, [(name, further attributes, array), ...]) in file order
    elements = [
        ("FieldData", field_arrays),
        ("Points", [("Points", {"NumberOfComponents": 3}, flat_points(X))]),
        (
            "Cells",
            [
                ("connectivity", {}, connectivity),
                ("offsets", {}, np.arange(1, cell_count + 1, dtype=np.int64) * corner_count),
                ("types", {}, np.full(cell_count, VTK_HEXAHEDRON if len(node_shape) == 3 else VTK_QUAD, dtype=np.uint8)),
            ],
        ),
        ("CellData", [(name, {}, values) for name, values in cell_data.items()]),
    ]
    elements = [(element, [(name, more, _little_endian(a)) for name, more, a in arrays]) for element, arrays in elements]

    pool = ThreadPoolExecutor(max_workers=_cpu_count())
    try:
        compress = functools.partial(compress_block, level=level, rle_above=rle_above)
        compressed = compressed_arrays(pool, [a for _, arrays in elements for *_, a in arrays], compress, block_bytes)
        with open(path, "wb") as file:
            file.write(FILE_HEAD)
            for element, arrays in elements:
                if element == "Points":
                    file.write(f'<Piece NumberOfPoints="{int(np.prod(node_shape))}" NumberOfCells="{cell_count}">\n'.encode())
                if arrays:
                    file.write(f"<{element}>\n".encode())
                    for (name, more, array), (header, streams) in zip(arrays, compressed):
                        _write_data_array(file, name, more, array.dtype, header, streams)
                    file.write(f"</{element}>\n".encode())
            file.write(b"</Piece>\n</UnstructuredGrid>\n</VTKFile>\n")
    finally:
        pool.shutdown(cancel_futures=True)  # after a failure (or Ctrl-C), drop the blocks not yet started


def compress_block(block, level: int = LEVEL, rle_above: float | None = RLE_ABOVE) -> bytes:
    """One zlib stream of ``block`` (bytes-like): deflate at ``level``; but where its first
    ``PROBE_BYTES`` deflated at ``level`` keep more than ``rle_above`` of their size (None: never),
    deflate with run-length matches only (Z_RLE). Any zlib reader inflates either."""
    probe = zlib.compress(block[:PROBE_BYTES], level)
    if rle_above is not None and len(probe) > rle_above * min(len(block), PROBE_BYTES):
        compressor = zlib.compressobj(level, zlib.DEFLATED, zlib.MAX_WBITS, 8, zlib.Z_RLE)
        return compressor.compress(block) + compressor.flush()
    return probe if len(block) <= PROBE_BYTES else zlib.compress(block, level)


def compressed_arrays(pool, arrays, compress=compress_block, block_bytes: int = BLOCK_BYTES):
    """Iterate over C-contiguous ``arrays`` compressed as VTK stores them: per array
    ``(header, streams)``, the compression header (bytes) and the zlib stream of each block,
    ``compress(block)``. The blocks of all arrays go to ``pool`` at once, so later arrays are
    compressed while the caller writes earlier ones."""
    views = [memoryview(array).cast("B") for array in arrays]
    blocks = [view[start : start + block_bytes] for view in views for start in range(0, len(view), block_bytes)]
    streams_in_order = pool.map(compress, blocks)
    for view in views:
        streams = [next(streams_in_order) for _ in range(0, len(view), block_bytes)]
        header = np.array([len(streams), block_bytes, len(view) % block_bytes, *map(len, streams)], dtype=HEADER_TYPE)
        yield header.tobytes(), streams


def _connectivity(node_shape) -> np.ndarray:
    """The cells of ``meshgen.grid.cell_connectivity``, (cells, 8 or 4) int64, as one broadcast sum:
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
    """One DataArray element: the base64 of the header, then that of the streams joined."""
    attributes = "".join(f' {key}="{value}"' for key, value in more.items())
    file.write(f'<DataArray type="{VTK_TYPES[dtype]}" Name={quoteattr(name)}{attributes} format="binary">\n'.encode())
    file.write(base64.b64encode(header))
    file.write(base64.b64encode(b"".join(streams)))
    file.write(b"\n</DataArray>\n")


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def read(path):
    """Read a .vtu (ours or any other) with meshio."""
    import meshio

    return meshio.read(path, file_format="vtu")
