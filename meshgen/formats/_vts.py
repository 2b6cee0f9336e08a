"""VTK XML structured grid (.vts): ParaView's own format for a structured mesh. Only the points
are stored (no connectivity, offsets or cell types), compressed in blocks on all cores as the
.vtu writer does (``meshgen.formats._vtu``), but as raw appended data (no base64, the 4/3 of
the .vtu's inline arrays) and with the quality arrays in Float32 (7 significant digits; the
points stay Float64). A 100^3 neural mesh with its seven quality arrays: less than half the
.vtu's size (benchmarks/formats.py).

The file, VTK's XML format version 1.0 as ParaView writes it by default (appended, raw)::

    <VTKFile type="StructuredGrid" version="1.0" byte_order="LittleEndian"
             header_type="UInt64" compressor="vtkZLibDataCompressor">
      <StructuredGrid WholeExtent="0 n1 0 n2 0 n3">       (2D: "0 n1 0 n2 0 0")
        <FieldData>   UInt8 "meshgen": the metadata's JSON bytes (only with metadata)
                      UInt8 "meshgen_patches": JSON [{"name", "type", "faces"}] of the patches
        <Piece Extent="0 n1 0 n2 0 n3">
          <PointData> Int32 "patch": index into meshgen_patches of the patch a boundary node
                      lies on, -1 inside; on an edge or corner shared by several patches, the
                      one listed first
          <CellData>  one Float32 array per name (the quality arrays)
          <Points>    Float64, 3 components (2D meshes: z = 0)
        </Piece>
      </StructuredGrid>
      <AppendedData encoding="raw">_ then, per array at its offset: the compression header
      (UInt64: blocks, block size, last block size or 0, compressed size of each block) and the
      zlib streams of its blocks
    </VTKFile>

VTK's structured order runs i fastest, so points and cell arrays are written transposed from
meshgen's C order (k fastest) and the reader transposes them back.
"""

from __future__ import annotations

import base64
import json
import xml.etree.ElementTree as ET
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple

import numpy as np

from meshgen.errors import FormatError, MeshgenError
from meshgen.formats._vtu import (
    BLOCK_BYTES,
    VTK_TYPES,
    compress_block,
    compress_blocks,
    compression_header,
    cpu_count,
)
from meshgen.formats._xml import quoteattr
from meshgen.formats.metadata import METADATA_KEY, metadata_json
from meshgen.geometry import cube
from meshgen.geometry.grid import cell_connectivity
from meshgen.geometry.patches import as_records, from_records
from meshgen.run.inputs import InputError, inflate
from meshgen.run.limits import READ_BYTES_PER_NODE, check_memory, node_count

__all__ = [
    "FILE_TAIL",
    "Grid",
    "NUMPY_TYPES",
    "PATCHES_KEY",
    "PATCH_ARRAY",
    "TYPES",
    "block_extent",
    "data_array",
    "decode_array",
    "field_arrays",
    "file_head",
    "parse_xml",
    "patch_ids",
    "read",
    "read_grid",
    "read_patches",
    "whole_extent",
    "writable",
    "write",
]

PATCHES_KEY = "meshgen_patches"
PATCH_ARRAY = "patch"
TYPES = {**VTK_TYPES, np.dtype("<i4"): "Int32", np.dtype("<f4"): "Float32"}
NUMPY_TYPES = {
    "Float64": "<f8",
    "Float32": "<f4",
    "Int64": "<i8",
    "Int32": "<i4",
    "UInt8": "u1",
    "UInt64": "<u8",
    "UInt32": "<u4",
}


def write(path, X, cell_data, metadata, patches, block=None, whole_shape=None):
    """Write node array ``X`` (n1+1, n2+1[, n3+1], dim) as a compressed .vts with ``cell_data``
    (name -> (cells,) float64, C order of the cells), ``metadata`` and ``patches``
    (``meshgen.geometry.patches.Patch``). A piece of a .pvts: ``X`` is the nodes ``block`` (one slice per
    axis) of a mesh of ``whole_shape`` nodes, whose index range is the file's extent."""
    node_shape = X.shape[:-1]
    dim = len(node_shape)
    cell_shape = tuple(n - 1 for n in node_shape)
    block = block or tuple(slice(0, n) for n in node_shape)
    extent = block_extent(block)
    order = tuple(range(dim - 1, -1, -1))  # VTK's i-fastest order
    pool = ThreadPoolExecutor(max_workers=cpu_count())
    sections = {"FieldData": [], "PointData": [], "CellData": [], "Points": []}

    def add(section, name, values, more=None):
        values = np.ascontiguousarray(values)
        sections[section].append((name, more or {}, values.dtype, values.nbytes, compress_blocks(pool, values, compress_block)))

    try:
        points = np.zeros(tuple(reversed(node_shape)) + (3,))
        points[..., :dim] = np.transpose(X, order + (dim,))
        add("Points", "Points", points, {"NumberOfComponents": 3})
        for name, values in cell_data.items():
            add("CellData", name, np.transpose(np.reshape(values, cell_shape), order).astype("<f4"))
        add("PointData", PATCH_ARRAY, np.transpose(patch_ids(whole_shape or node_shape, patches, block), order))
        for name, more, codes in field_arrays(metadata, patches):
            add("FieldData", name, codes, more)

        # The offsets in the XML need every array's compressed size: wait for all of them.
        parts, offset, elements = [], 0, {}
        for section in ("FieldData", "PointData", "CellData", "Points"):
            lines = []
            for name, more, dtype, nbytes, blocks in sections[section]:
                streams = [block.result() for block in blocks]
                header = compression_header(nbytes, BLOCK_BYTES, streams)
                lines.append(data_array(dtype, name, more, offset))
                parts += [header, *streams]
                offset += len(header) + sum(map(len, streams))
            elements[section] = f"<{section}>\n{''.join(lines)}</{section}>\n" if lines else ""

        with open(path, "wb") as file:
            file.write(file_head(extent, elements))
            for part in parts:
                file.write(part)
            file.write(FILE_TAIL)
    finally:
        pool.shutdown(cancel_futures=True)


def patch_ids(node_shape, patches, block=None) -> np.ndarray:
    """(n1+1, n2+1[, n3+1]) int32: the index of the patch each boundary node lies on (the first
    listed where patches meet), -1 inside; of the nodes ``block`` only (one slice per axis), if given."""
    node_shape = tuple(int(n) for n in node_shape)
    block = block or tuple(slice(0, n) for n in node_shape)
    ids = np.full(tuple(s.stop - s.start for s in block), -1, dtype=np.int32)
    for number in range(len(patches) - 1, -1, -1):  # the first listed is written last and wins
        for face_name in patches[number].faces:
            face = cube.face_named(face_name, len(node_shape))
            end = node_shape[face.axis] - 1 if face.side else 0
            if block[face.axis].start <= end < block[face.axis].stop:
                ids[tuple(end - s.start if d == face.axis else slice(None) for d, s in enumerate(block))] = number
    return ids


def data_array(dtype, name: str, more: dict, offset: int) -> str:
    """The XML line of an appended DataArray at ``offset`` in the appended data."""
    attributes = "".join(f' {key}="{value}"' for key, value in more.items())
    return (
        f'<DataArray type="{TYPES[np.dtype(dtype)]}" Name={quoteattr(name)}{attributes} format="appended" offset="{offset}"/>\n'
    )


def file_head(extent: str, elements: dict) -> bytes:
    """The file up to its appended data: ``elements`` maps FieldData, PointData, CellData, Points
    to their XML ('' for none)."""
    return (
        '<?xml version="1.0"?>\n<VTKFile type="StructuredGrid" version="1.0" byte_order="LittleEndian" '
        'header_type="UInt64" compressor="vtkZLibDataCompressor">\n'
        f'<StructuredGrid WholeExtent="{extent}">\n{elements["FieldData"]}<Piece Extent="{extent}">\n'
        f"{elements['PointData']}{elements['CellData']}{elements['Points']}</Piece>\n</StructuredGrid>\n"
        '<AppendedData encoding="raw">\n_'
    ).encode()


FILE_TAIL = b"\n</AppendedData>\n</VTKFile>\n"


def block_extent(block) -> str:
    """VTK's extent of the nodes ``block`` (one slice per axis): first and last index per axis."""
    return " ".join(f"{s.start} {s.stop - 1}" for s in block) + (" 0 0" if len(block) == 2 else "")


def whole_extent(node_shape) -> str:
    return block_extent(tuple(slice(0, int(n)) for n in node_shape))


def field_arrays(metadata, patches) -> list:
    """[(name, more, values)] of the FieldData: the metadata's JSON bytes (if any) and the patches'."""
    arrays = []
    if metadata:
        codes = np.frombuffer(metadata_json(metadata).encode("ascii"), dtype=np.uint8)
        arrays.append((METADATA_KEY, {"NumberOfTuples": codes.size}, codes))
    codes = np.frombuffer(json.dumps(as_records(patches)).encode("ascii"), dtype=np.uint8)
    arrays.append((PATCHES_KEY, {"NumberOfTuples": codes.size}, codes))
    return arrays


# --- reading ---------------------------------------------------------------------------------


def parse_xml(path, grid_type: str = "StructuredGrid"):
    """(XML root, raw appended bytes or None) of a VTK XML file of ``grid_type`` (its root's
    ``type``: "StructuredGrid", "UnstructuredGrid"); FormatError for another file."""
    data = open(path, "rb").read()
    appended = None
    start = data.find(b"<AppendedData")
    if start >= 0:
        tag_end = data.index(b">", start)
        if b'encoding="raw"' not in data[start:tag_end]:
            raise FormatError(f"{path}: base64 appended data is not read (meshgen reads raw appended or inline arrays)")
        appended = memoryview(data)[data.index(b"_", tag_end) + 1 :]
        data = data[:start] + b"</VTKFile>"
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        raise FormatError(f"{path}: not a VTK XML file ({exc})") from None
    if root.get("type") != grid_type:
        raise FormatError(f"{path}: not a VTK {grid_type} file")
    return root, appended


def decode_array(element, root, appended=None, count: int | None = None, what: str = "a DataArray", pool=None) -> np.ndarray:
    """The values of a DataArray: ascii, inline binary, or raw appended, with or without zlib
    compression. ``count``: the number of values the file's extent implies; the sizes the array
    declares are compared with it before anything is inflated, and each zlib stream is inflated
    to at most its declared size (``inputs.inflate``): a stream of a few MB that would inflate to
    gigabytes is refused, not inflated. ``pool``: an executor that inflates the blocks on its
    threads (zlib releases the GIL). FormatError for an array that does not hold its values."""
    dtype = np.dtype(NUMPY_TYPES[element.get("type")])
    header_type = np.dtype(NUMPY_TYPES[root.get("header_type", "UInt32")])
    compressed = root.get("compressor") == "vtkZLibDataCompressor"
    expected = None if count is None else int(count) * dtype.itemsize
    if element.get("format") == "ascii":
        values = np.array((element.text or "").split(), dtype=dtype)
        return _counted(values, count, what)
    if element.get("format") == "appended":
        if appended is None:
            raise FormatError(f"{what} is appended but the file has no appended data")
        raw = appended[int(element.get("offset")) :]
    else:
        text = (element.text or "").strip()
        raw = None
    if not compressed:
        if raw is None:
            raw = base64.b64decode(text)
        size = int(np.frombuffer(bytes(raw[: header_type.itemsize]), dtype=header_type)[0])
        _check_size(size, expected, what)
        body = raw[header_type.itemsize : header_type.itemsize + size]
        if len(body) < size:
            raise FormatError(f"{what} declares {size} bytes but the file holds {len(body)}: truncated")
        return _counted(np.frombuffer(body, dtype=dtype), count, what)
    if raw is not None:  # appended: the header, then the streams
        blocks = int(np.frombuffer(bytes(raw[: header_type.itemsize]), dtype=header_type)[0])
        header_bytes = (3 + blocks) * header_type.itemsize
        if header_bytes > len(raw):
            raise FormatError(f"{what} declares {blocks} compressed blocks but the file ends before their sizes")
        header = np.frombuffer(bytes(raw[:header_bytes]), dtype=header_type).astype(np.int64)
        stream = raw[header_bytes:]
    else:  # inline: the header and the streams are base64-encoded separately (as VTK writes them)
        first = base64.b64decode(text[: 4 * -(-header_type.itemsize // 3)])
        blocks = int(np.frombuffer(first[: header_type.itemsize], dtype=header_type)[0])
        header_bytes = (3 + blocks) * header_type.itemsize
        header_chars = 4 * -(-header_bytes // 3)
        if header_chars > len(text):
            raise FormatError(f"{what} declares {blocks} compressed blocks but the file ends before their sizes")
        header = np.frombuffer(base64.b64decode(text[:header_chars])[:header_bytes], dtype=header_type).astype(np.int64)
        stream = base64.b64decode(text[header_chars:])
    block_size, last_size, sizes = int(header[1]), int(header[2]), header[3:]
    inflated = [block_size] * blocks
    if blocks and last_size:
        inflated[-1] = last_size
    _check_size(sum(inflated), expected, what)
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    if blocks and offsets[-1] > len(stream):
        raise FormatError(f"{what} declares {int(offsets[-1])} compressed bytes but the file holds {len(stream)}: truncated")

    def block(n):
        return inflate(stream[offsets[n] : offsets[n + 1]], inflated[n], f"{what}, block {n + 1}")

    try:
        values = b"".join(pool.map(block, range(blocks)) if pool is not None and blocks > 1 else map(block, range(blocks)))
    except InputError as exc:
        raise FormatError(str(exc)) from None
    return _counted(np.frombuffer(values, dtype=dtype), count, what)


def _check_size(size: int, expected: int | None, what: str) -> None:
    if expected is not None and size != expected:
        raise FormatError(f"{what} declares {size} bytes but the file's extent implies {expected}: not this grid's array")


def _counted(values: np.ndarray, count: int | None, what: str) -> np.ndarray:
    if count is not None and len(values) != count:
        raise FormatError(f"{what} holds {len(values)} values but the file's extent implies {count}")
    return values


class Grid(NamedTuple):
    """A .vts file as ``read_grid`` reads it: ``node_shape`` (n1+1, n2+1[, n3+1]); ``points``
    (N, 3) float64 in meshgen's C order of the nodes; ``cell_data`` {name: [(cells,) float64]} and
    ``point_data`` {name: (N,)} in C order (meshio's layout); ``field_data`` {name: uint8 codes}
    (meshgen's metadata and patches). No connectivity: ``cell_connectivity(node_shape)`` is it."""

    node_shape: tuple
    points: np.ndarray
    cell_data: dict
    point_data: dict
    field_data: dict


def read_grid(path, cell_arrays=None, point_arrays=None, on_shape=None) -> Grid:
    """Read a .vts (one piece) as a ``Grid``: the points, the cell and point arrays named in
    ``cell_arrays`` and ``point_arrays`` (None: all; the others are not inflated) and meshgen's
    field data. The compressed blocks of each array are inflated on all cores.
    ``on_shape(node_shape)``: called once the extent is known, before anything is inflated."""
    root, appended = parse_xml(path)
    grid = root.find("StructuredGrid")
    pieces = grid.findall("Piece")
    if len(pieces) != 1:
        raise FormatError(f"{path}: {len(pieces)} pieces; meshgen reads single-piece files")
    bounds = [int(v) for v in pieces[0].get("Extent", grid.get("WholeExtent")).split()]
    counts = [bounds[2 * d + 1] - bounds[2 * d] + 1 for d in range(3)]
    node_shape = tuple(counts[:2]) if counts[2] == 1 else tuple(counts)
    dim = len(node_shape)
    order = tuple(range(dim - 1, -1, -1))

    def c_order(values, shape, components=1):
        array = values.reshape(tuple(reversed(shape)) + ((components,) if components > 1 else ()))
        return np.transpose(array, order + ((dim,) if components > 1 else ())).reshape((-1, components) if components > 1 else -1)

    if any(n < 1 for n in counts):
        raise FormatError(f"{path}: extent {bounds} holds no nodes")
    nodes = node_count(n - 1 for n in node_shape)
    try:
        check_memory(nodes * READ_BYTES_PER_NODE, f"{path}: reading its {' x '.join(map(str, node_shape))} nodes")
    except MeshgenError as exc:
        raise FormatError(str(exc)) from None
    cells = int(np.prod([n - 1 for n in node_shape]))
    if on_shape is not None:
        on_shape(node_shape)

    def wanted(elements, names):
        return [a for a in elements if names is None or a.get("Name") in names]

    with ThreadPoolExecutor(max_workers=cpu_count(), thread_name_prefix="meshgen-vts") as pool:

        def decode(element, count, name):
            if element is None:
                raise FormatError(f"{path}: no {name} array")
            return decode_array(element, root, appended, count, f"{path}: the {name} array", pool)

        points = writable(
            c_order(decode(pieces[0].find("Points/DataArray"), 3 * nodes, "points").astype(float, copy=False), node_shape, 3)
        )
        cell_shape = tuple(n - 1 for n in node_shape)
        cell_data = {
            a.get("Name"): [c_order(decode(a, cells, f"cell data {a.get('Name')!r}").astype(float), cell_shape)]
            for a in wanted(pieces[0].findall("CellData/DataArray"), cell_arrays)
        }
        point_data = {
            a.get("Name"): c_order(decode(a, nodes, f"point data {a.get('Name')!r}"), node_shape)
            for a in wanted(pieces[0].findall("PointData/DataArray"), point_arrays)
        }
    field_data = {a.get("Name"): decode_array(a, root, appended).copy() for a in grid.findall("FieldData/DataArray")}
    field_data = {k: v for k, v in field_data.items() if k in (METADATA_KEY, PATCHES_KEY)}
    return Grid(node_shape, points, cell_data, point_data, field_data)


def writable(values: np.ndarray) -> np.ndarray:
    """``values``, copied where they are a view of the file's (read-only) bytes."""
    return values if values.flags.writeable else values.copy()


def read(path):
    """Read a .vts (one piece, inline arrays) as a ``meshio.Mesh``: points and hexahedron (quad)
    cells in meshgen's C order, cell data, point data, meshgen's metadata in field data."""
    import meshio

    grid = read_grid(path)
    return meshio.Mesh(
        grid.points,
        [("hexahedron" if len(grid.node_shape) == 3 else "quad", cell_connectivity(grid.node_shape))],
        point_data=grid.point_data,
        cell_data=grid.cell_data,
        field_data=grid.field_data,
    )


def read_patches(path) -> list:
    codes = read_grid(path, cell_arrays=(), point_arrays=()).field_data.get(PATCHES_KEY)
    if codes is None:
        raise FormatError(f"{path}: no {PATCHES_KEY} field data (not written by meshgen)")
    return from_records(json.loads(np.asarray(codes, dtype=np.uint8).tobytes()))
