"""VTK XML partitioned structured grid (.pvts): the mesh as pieces, each a .vts of a slab of the
last index axis (k; 2D: j) in the folder ``<name>/`` beside ``<name>.pvts``, which lists them with
their extents. ParaView opens the .pvts as one grid and can read the pieces in parallel; a mesh
larger than memory is written piece by piece (``write_streamed``).

    <VTKFile type="PStructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">
      <PStructuredGrid WholeExtent="0 n1 0 n2 0 n3" GhostLevel="0">
        <PPointData> Int32 "patch" </PPointData>   <PCellData> a Float32 array per name </PCellData>
        <PPoints> Float64, 3 components </PPoints>
        <Piece Extent="0 n1 0 n2 k0 k1" Source="<name>/<name>_0.vts"/>  ...

Pieces are slabs of about ``PIECE_NODES`` nodes (whatever the memory: the same mesh gives the same
files in memory and block by block); neighbouring pieces share their node plane, so every cell is
in exactly one piece. Each piece is a .vts of ``meshgen.formats._vts`` with the mesh's extents (its
patch ids those of the whole mesh) and meshgen's metadata and patches in its field data. The
pieces' folder and the .pvts take their names together (``meshgen.run.publish``).
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from meshgen.errors import FormatError
from meshgen.formats._vts import PATCH_ARRAY, block_extent, whole_extent
from meshgen.formats._vts import read as read_piece
from meshgen.formats._vts import read_patches as read_piece_patches
from meshgen.formats._vts import write as write_piece
from meshgen.formats._xml import quoteattr
from meshgen.formats.streamed import NodeFile, slab_slices
from meshgen.geometry.grid import cell_connectivity
from meshgen.run.atomic import atomic_path, check_pieces_folder
from meshgen.run.publish import current_publication

__all__ = ["PIECE_NODES", "check_target", "piece_slices", "read", "read_patches", "write", "write_streamed"]

PIECE_NODES = 1 << 22  # nodes per piece, at most about: 100 MB of coordinates


def check_target(path) -> None:
    """FormatError when ``<name>/`` beside ``path`` exists and is not the pieces folder of an
    earlier .pvts (files ``<name>_N.vts`` only): writing would replace it."""
    name = re.escape(Path(path).stem)
    check_pieces_folder(
        path, lambda entry: re.fullmatch(rf"{name}_\d+\.vts", entry) is not None, f"files {Path(path).stem}_N.vts"
    )


def piece_slices(node_shape, piece_nodes: int = PIECE_NODES) -> list[slice]:
    """The node ranges of the pieces along the last axis: slabs of about ``piece_nodes`` nodes,
    each sharing its last node plane with the next one."""
    last = int(node_shape[-1])
    cells = slab_slices(tuple(node_shape[:-1]) + (last - 1,), len(node_shape) - 1, piece_nodes)
    return [slice(s.start, s.stop + 1) for s in cells]


def write(path, X, cell_data, metadata, patches, piece_nodes: int = PIECE_NODES) -> None:
    """Write node array ``X`` as pieces and the .pvts at ``path``; ``cell_data`` split with them."""
    node_shape = X.shape[:-1]
    cell_shape = tuple(n - 1 for n in node_shape)
    last = len(node_shape) - 1

    def pieces():
        for part in piece_slices(node_shape, piece_nodes):
            block = tuple(part if d == last else slice(0, n) for d, n in enumerate(node_shape))
            cells = tuple(slice(part.start, part.stop - 1) if d == last else slice(0, n) for d, n in enumerate(cell_shape))
            yield block, X[block], {name: np.reshape(values, cell_shape)[cells].reshape(-1) for name, values in cell_data.items()}

    _write_pieces(path, node_shape, pieces(), list(cell_data), metadata, patches)


def write_streamed(path, nodes: NodeFile, metadata: dict, patches, piece_nodes: int = PIECE_NODES) -> None:
    """``write`` of the mesh in ``nodes`` (``meshgen.formats.streamed.NodeFile``), piece by piece."""
    node_shape, last = tuple(nodes.node_shape), nodes.dim - 1

    def pieces():
        for part in piece_slices(node_shape, piece_nodes):
            block = tuple(part if d == last else slice(0, n) for d, n in enumerate(node_shape))
            yield block, nodes.read(last, part), {}

    _write_pieces(path, node_shape, pieces(), [], metadata, patches)


def _write_pieces(path, node_shape, pieces, cell_names, metadata, patches) -> None:
    """The pieces into ``<name>/`` and the .pvts listing them at ``path``. Inside a publication
    (``write_mesh``, ``write_chunked_mesh``), ``path`` is a temporary name of the publication's
    output: the folder is named after that output and staged with it."""
    publication = current_publication()
    target = Path(publication.output if publication is not None else path)
    folder = target.with_suffix("")
    lines = []
    with atomic_path(folder, folder=True) as temporary:
        for number, (block, X, cell_data) in enumerate(pieces):
            name = f"{folder.name}_{number}.vts"
            write_piece(temporary / name, X, cell_data, metadata, patches, block, node_shape)
            lines.append(f"    <Piece Extent={quoteattr(block_extent(block))} Source={quoteattr(f'{folder.name}/{name}')}/>\n")
    cells = "".join(f'      <PDataArray type="Float32" Name={quoteattr(name)}/>\n' for name in cell_names)
    Path(path).write_text(
        '<?xml version="1.0"?>\n<VTKFile type="PStructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">\n'
        f'  <PStructuredGrid WholeExtent="{whole_extent(node_shape)}" GhostLevel="0">\n'
        f'    <PPointData>\n      <PDataArray type="Int32" Name="{PATCH_ARRAY}"/>\n    </PPointData>\n'
        + (f"    <PCellData>\n{cells}    </PCellData>\n" if cells else "")
        + '    <PPoints>\n      <PDataArray type="Float64" NumberOfComponents="3"/>\n    </PPoints>\n'
        + "".join(lines)
        + "  </PStructuredGrid>\n</VTKFile>\n"
    )


def _pieces(path) -> tuple[tuple[int, ...], list]:
    """(node shape, [(node block, piece path)]) of a .pvts."""
    try:
        grid = ET.parse(path).getroot().find("PStructuredGrid")
    except ET.ParseError as exc:
        raise FormatError(f"{path}: not a VTK XML file ({exc})") from None
    if grid is None:
        raise FormatError(f"{path}: not a VTK PStructuredGrid file")
    bounds = [int(v) for v in grid.get("WholeExtent", "").split()]
    dim = 2 if bounds[4] == bounds[5] else 3
    node_shape = tuple(bounds[2 * d + 1] - bounds[2 * d] + 1 for d in range(dim))
    pieces = []
    for piece in grid.findall("Piece"):
        extent = [int(v) for v in piece.get("Extent").split()]
        block = tuple(slice(extent[2 * d], extent[2 * d + 1] + 1) for d in range(dim))
        pieces.append((block, Path(path).parent / piece.get("Source")))
    return node_shape, pieces


def read(path):
    """Read a .pvts meshgen wrote as one ``meshio.Mesh`` (its pieces put together): points and
    cells in meshgen's C order, the pieces' cell and point data, meshgen's metadata."""
    import meshio

    node_shape, pieces = _pieces(path)
    dim = len(node_shape)
    cell_shape = tuple(n - 1 for n in node_shape)
    X = np.zeros(node_shape + (3,))
    point_data, cell_data, field_data = {}, {}, {}
    for block, piece_path in pieces:
        piece = read_piece(piece_path)
        shape = tuple(s.stop - s.start for s in block)
        X[block] = piece.points.reshape(shape + (3,))
        cells = tuple(slice(s.start, s.stop - 1) for s in block)
        for name, values in piece.point_data.items():
            point_data.setdefault(name, np.zeros(node_shape, dtype=values.dtype))[block] = values.reshape(shape)
        for name, (values,) in piece.cell_data.items():
            cell_data.setdefault(name, np.zeros(cell_shape))[cells] = values.reshape(tuple(n - 1 for n in shape))
        field_data = field_data or piece.field_data
    return meshio.Mesh(
        X.reshape(-1, 3),
        [("hexahedron" if dim == 3 else "quad", cell_connectivity(node_shape))],
        point_data={k: v.reshape(-1) for k, v in point_data.items()},
        cell_data={k: [v.reshape(-1)] for k, v in cell_data.items()},
        field_data=field_data,
    )


def read_patches(path) -> list:
    _, pieces = _pieces(path)
    if not pieces:
        raise FormatError(f"{path}: no pieces")
    return read_piece_patches(pieces[0][1])
