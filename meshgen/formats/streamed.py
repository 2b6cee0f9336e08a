"""Writing a mesh larger than memory in the formats that list its nodes in one fixed order
(OpenFOAM, .vts, Plot3D, .su2, .msh), slab by slab from a node file.

The chunked path (``meshgen.run.chunked``) computes blocks in the order they complete, so it first
streams them into a scratch CGNS file (random-access hyperslab writes), then a format's
``write_streamed(path, nodes, metadata, patches)`` reads that file back in slabs of
``NodeFile.block_nodes`` nodes in the order the format lists its nodes: slabs of the first
axis (i) for the formats in C order (OpenFOAM, .su2, .msh: k fastest), slabs of the last axis (k)
for those in Fortran order (.vts, Plot3D: i fastest). Connectivity (cells, faces, owners) is
label arithmetic on a slab's index range, so nothing of the whole mesh's size is ever held: memory
is a few slabs (design notes §21).

What needs the whole mesh before the first byte (a map's orientation, which sets the faces'
winding; the bounding box a .msh lists first; a 2D mesh's area, its OpenFOAM extrusion's
thickness) is one reading pass over the slabs, summed (min/max) as they come.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshgen.formats import format_named
from meshgen.formats._cgns import read_node_block
from meshgen.formats._structured import corner_volume, node_labels, write_rows
from meshgen.geometry.grid import BLOCK_NODES, HEX_CORNERS, QUAD_CORNERS

__all__ = [
    "NodeFile",
    "bounding_box",
    "cell_slabs",
    "cells_of_slab",
    "list_end",
    "list_start",
    "list_values",
    "map_orientation",
    "slab_slices",
    "write_streamed",
]


def slab_slices(node_shape, axis: int, block_nodes: int = BLOCK_NODES) -> list[slice]:
    """Slices along ``axis`` of slabs of at most about ``block_nodes`` nodes (at least one plane)."""
    node_shape = tuple(int(n) for n in node_shape)
    plane = int(np.prod(node_shape)) // node_shape[axis]
    step = max(1, block_nodes // max(1, plane))
    return [slice(s, min(s + step, node_shape[axis])) for s in range(0, node_shape[axis], step)]


@dataclass(frozen=True)
class NodeFile:
    """A structured mesh's nodes in a CGNS file (one zone), read in slabs: ``node_shape`` (n1+1,
    n2+1[, n3+1]); ``block_nodes``: nodes per slab, at most about."""

    path: Path
    node_shape: tuple
    block_nodes: int = BLOCK_NODES

    @property
    def dim(self) -> int:
        return len(self.node_shape)

    def slabs(self, axis: int) -> list[slice]:
        return slab_slices(self.node_shape, axis, self.block_nodes)

    def read(self, axis: int, part: slice, overlap: int = 0) -> np.ndarray:
        """The nodes of slab ``part`` along ``axis`` (grown by ``overlap`` nodes at its end, within
        the mesh): block shape + (dim,), float64, C order."""
        stop = min(part.stop + overlap, self.node_shape[axis])
        block = tuple(slice(part.start, stop) if d == axis else slice(0, n) for d, n in enumerate(self.node_shape))
        return read_node_block(self.path, block)


def cell_slabs(node_shape, block_nodes: int = BLOCK_NODES) -> list[slice]:
    """Slabs of cell planes along the first axis (i) with about ``block_nodes`` cells each."""
    return slab_slices([n - 1 for n in node_shape], 0, block_nodes)


def cells_of_slab(node_shape, part: slice) -> np.ndarray:
    """``meshgen.geometry.grid.cell_connectivity``'s rows of the cells whose i index is in ``part``: (cells,
    8 or 4) int64 labels of the C-order nodes, VTK corner order, cells in C order."""
    node_shape = tuple(int(n) for n in node_shape)
    corners = HEX_CORNERS if len(node_shape) == 3 else QUAD_CORNERS
    strides = np.cumprod((1,) + node_shape[:0:-1])[::-1]
    first = node_labels(node_shape, (part,) + tuple(slice(0, n - 1) for n in node_shape[1:])).reshape(-1)
    return first[:, None] + (corners @ strides)[None, :]


def map_orientation(nodes: NodeFile) -> float:
    """+1 for a right-handed (2D: counterclockwise) map, else -1, as ``_structured.orientation``
    of the whole array: the sign of the corner volumes summed slab by slab."""
    total = sum(corner_volume(nodes.read(0, part, overlap=1)) for part in nodes.slabs(0) if part.start < nodes.node_shape[0] - 1)
    return 1.0 if total >= 0 else -1.0


def bounding_box(nodes: NodeFile) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) per component of the nodes, slab by slab."""
    low, high = np.full(nodes.dim, np.inf), np.full(nodes.dim, -np.inf)
    for part in nodes.slabs(0):
        slab = nodes.read(0, part).reshape(-1, nodes.dim)
        low, high = np.minimum(low, slab.min(axis=0)), np.maximum(high, slab.max(axis=0))
    return low, high


def list_start(file, count: int, binary: bool) -> None:
    """The opening of an OpenFOAM list of ``count`` entries (``meshgen.formats._openfoam.write_list``)."""
    file.write(f"{count}\n(".encode() if binary else f"{count}\n(\n".encode())


def list_values(file, values: np.ndarray, binary: bool, row: str = "{}") -> None:
    """Entries of an OpenFOAM list: raw little-endian bytes (binary) or one ``row`` a line."""
    if binary:
        data = np.ascontiguousarray(values, dtype="<f8" if values.dtype.kind == "f" else "<i4")
        file.write(memoryview(data).cast("B"))
    else:
        write_rows(file, values, row)


def list_end(file) -> None:
    file.write(b")\n\n")


def write_streamed(path, nodes: NodeFile, format_name: str, metadata: dict, patches, **options) -> None:
    """Write the mesh of ``nodes`` to ``path`` (a temporary file the caller publishes; an
    OpenFOAM case folder, which publishes itself) in the format ``format_name``."""
    module = importlib.import_module(format_named(format_name).streamed)
    module.write_streamed(path, nodes, metadata, patches, **options)
