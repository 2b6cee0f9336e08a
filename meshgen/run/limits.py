"""Sizes and numbers, checked before anything is allocated (design notes, "Trust boundary and
faults").

Every number meshgen reads (a flag, a ``--set`` value, a gate, a file's header) is finite and
inside bounds, and every size is checked against the memory available now, and the disk where it
writes, before the first large allocation: a request too large for the machine is one line that
says how large it is, what is available and which path could take it (the chunked path for
meshes larger than memory), never a MemoryError after seconds of work.
"""

from __future__ import annotations

import math

from meshgen.errors import MeshgenError, excerpt
from meshgen.geometry.grid import BLOCK_NODES
from meshgen.run.resources import IN_MEMORY_BYTES_PER_NODE, available_memory

__all__ = [
    "CHUNKED_FACE_COPIES",
    "MAX_COORDINATE",
    "SHAPE_BYTES_PER_FILE_BYTE",
    "READ_BYTES_PER_NODE",
    "CAD_BYTES_PER_FILE_BYTE",
    "CAD_MIN_BYTES",
    "TRAIN_BYTES_PER_ACTIVATION",
    "check_block_set_memory",
    "check_finite",
    "check_memory",
    "check_mesh_memory",
    "check_shape_memory",
    "cad_read_bytes",
    "check_training_memory",
    "chunked_mesh_bytes",
    "gigabytes",
    "in_memory_mesh_bytes",
    "node_count",
    "parse_finite",
    "training_bytes",
]

# Coordinates beyond this magnitude overflow the metrics (squared lengths, volumes): refused.
MAX_COORDINATE = 1e100
# The chunked mesh path keeps O(n^2) face arrays: the face values, their TFI terms, the correction
# terms and a temporary, each (face nodes, dim) float64.
CHUNKED_FACE_COPIES = 4
# Training: bytes per (point, hidden unit) held for one step: float32 activations, their first and
# second derivatives (the Winslow residual), and the gradients of all of them; measured order.
TRAIN_BYTES_PER_ACTIVATION = 4 * 24
# Reading a structured mesh file whole: the points (float64, padded to 3), the cells' connectivity
# (8 int64 a hexahedron), a copy of each while it is reordered: about this many bytes a node.
READ_BYTES_PER_NODE = 200
# A triangulated shape file's memory while it is read, per byte of the file: a binary STL's 50
# bytes a triangle become 72 of corner points, then the weld's scaled copies, integer cells and
# sort (about 10 copies); an ASCII STL's 250 bytes a triangle need less. Measured order, rounded up.
SHAPE_BYTES_PER_FILE_BYTE = 16
# The memory the CAD reader (gmsh, OpenCASCADE) may take to read a file: this many bytes per byte
# of the file, at least CAD_MIN_BYTES (a 45 kB STEP loft takes about 60 MB). A malformed STEP can
# make OCC allocate without end; the bound makes that a failed read in a second.
CAD_BYTES_PER_FILE_BYTE = 256
CAD_MIN_BYTES = 2**30


def check_finite(value, what: str) -> float:
    """``value`` as a float when it is a finite number, else MeshgenError naming ``what``."""
    number = float(value)
    if not math.isfinite(number):
        raise MeshgenError(f"{what} must be a finite number, got {number!r}")
    return number


def parse_finite(text: str, what: str) -> float:
    """The finite number written in ``text`` (inf, nan and non-numbers refused), else MeshgenError."""
    try:
        number = float(text)
    except (TypeError, ValueError):
        raise MeshgenError(f"{what}: {excerpt(repr(text))} is not a number") from None
    if not math.isfinite(number):
        raise MeshgenError(f"{what}: {excerpt(repr(text))} is not a finite number")
    return number


def gigabytes(n_bytes: float) -> str:
    return f"{n_bytes / 1e9:.3g} GB"


def check_memory(needed_bytes: float, what: str, hint: str = "") -> None:
    """MeshgenError when ``needed_bytes`` exceed the memory available now; ``hint`` says what to do."""
    available = available_memory()
    if needed_bytes > available:
        raise MeshgenError(
            f"{what} needs about {gigabytes(needed_bytes)} of memory but {gigabytes(available)} are available"
            + (f"; {hint}" if hint else "")
        )


def node_count(dims) -> int:
    """Nodes of a structured mesh of ``dims`` cells (an exact Python integer: no overflow)."""
    return math.prod(int(n) + 1 for n in dims)


def in_memory_mesh_bytes(dims) -> int:
    """The in-memory mesh path's peak memory for ``dims`` cells (``IN_MEMORY_BYTES_PER_NODE``)."""
    return node_count(dims) * IN_MEMORY_BYTES_PER_NODE


def chunked_mesh_bytes(dims) -> int:
    """The chunked mesh path's memory, whatever the block size: the 1D node coordinates, the
    boundary faces' arrays (``CHUNKED_FACE_COPIES`` of each) and a few blocks."""
    nodes = [int(n) + 1 for n in dims]
    dim = len(nodes)
    faces = sum(2 * math.prod(nodes[:axis] + nodes[axis + 1 :]) for axis in range(dim))
    return 8 * sum(nodes) + 8 * dim * CHUNKED_FACE_COPIES * faces + 8 * dim * 4 * BLOCK_NODES


def check_mesh_memory(dims, chunked: bool) -> None:
    """MeshgenError unless a mesh of ``dims`` cells fits in memory on the path it takes:
    ``chunked`` (blocks streamed into the file) or in memory."""
    shape = " x ".join(str(int(n)) for n in dims)
    # Too large even for the chunked path: say so, rather than suggest it.
    check_memory(
        chunked_mesh_bytes(dims), f"a {shape} mesh ({node_count(dims):.3g} nodes), even block by block,", "pick fewer cells"
    )
    if not chunked:
        check_memory(
            in_memory_mesh_bytes(dims),
            f"a {shape} mesh ({node_count(dims):.3g} nodes) in memory",
            "meshgen mesh --chunked -o FILE.cgns (or .vts, .su2, .msh, .xyz, --format openfoam; methods tfi, neural) "
            "writes meshes larger than memory block by block",
        )


def check_block_set_memory(block_dims, name: str) -> None:
    """MeshgenError unless the block set ``name`` of blocks of ``block_dims`` cells [(n1, n2[, n3])]
    fits in memory: a block set is meshed in memory (no chunked path), ``IN_MEMORY_BYTES_PER_NODE``
    per node of all its blocks, the limit a single block's mesh takes (``check_mesh_memory``)."""
    nodes = sum(node_count(dims) for dims in block_dims)
    check_memory(
        nodes * IN_MEMORY_BYTES_PER_NODE,
        f"the multi-block geometry '{name}' at these --dims ({len(block_dims)} blocks, {nodes:.3g} nodes) in memory",
        "pick fewer cells (block sets are meshed in memory)",
    )


def check_shape_memory(file_bytes: int, what: str) -> None:
    """MeshgenError unless a triangulated shape file of ``file_bytes`` bytes can be read and welded
    in the memory available now (``SHAPE_BYTES_PER_FILE_BYTE``)."""
    check_memory(int(file_bytes) * SHAPE_BYTES_PER_FILE_BYTE, f"{what} ({gigabytes(file_bytes)})", "a smaller surface file")


def cad_read_bytes(file_bytes: int) -> int:
    """The memory the CAD reader may allocate to read a CAD file of ``file_bytes`` bytes
    (``CAD_BYTES_PER_FILE_BYTE``, at least ``CAD_MIN_BYTES``); MeshgenError when even that
    is more than the memory available now."""
    needed = max(CAD_MIN_BYTES, int(file_bytes) * CAD_BYTES_PER_FILE_BYTE)
    check_memory(needed, f"reading a CAD file of {gigabytes(file_bytes)}", "a smaller CAD file")
    return needed


def training_bytes(widths, dim: int, points: int, history: int) -> int:
    """Training memory of a tanh MLP of hidden ``widths`` on ``points`` points per step: the
    weights with their gradients, Adam's two moments and L-BFGS's ``history`` pairs (float32),
    and the activations (``TRAIN_BYTES_PER_ACTIVATION`` per point and hidden unit)."""
    sizes = [dim, *(int(w) for w in widths), dim]
    parameters = sum((a + 1) * b for a, b in zip(sizes, sizes[1:]))
    return 4 * parameters * (4 + 2 * int(history)) + int(points) * sum(int(w) for w in widths) * TRAIN_BYTES_PER_ACTIVATION


def check_training_memory(widths, dim: int, points: int, history: int) -> None:
    """MeshgenError unless training this network on ``points`` points per step fits in memory."""
    check_memory(
        training_bytes(widths, dim, points, history),
        f"training a network of widths {excerpt(list(widths), 40)} on {points} points per step",
        "pick smaller model.widths or fewer points",
    )
