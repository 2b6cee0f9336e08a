"""The nodes of a block set (``meshgen.geometry.blocks.BlockSet``) as one mesh: which nodes of two
blocks an interface joins (``face_index``), global node numbers with interface nodes merged
(``global_numbering``), interface nodes checked and made identical (``interface_gaps``,
``unify_interfaces``), and the merged mesh (``merged_mesh``). Functions take the BlockSet and
per-block node arrays (n1+1, n2+1[, n3+1], dim); nothing here loads a geometry."""

from __future__ import annotations

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry.grid import cell_connectivity

__all__ = [
    "GAP_TOLERANCE",
    "face_index",
    "global_numbering",
    "interface_gaps",
    "interface_text",
    "merged_mesh",
    "unify_interfaces",
]

GAP_TOLERANCE = 1e-9  # largest gap between interface nodes, relative to the block set's size


def interface_text(block_set, a, fa, b, fb) -> str:
    """``block.face = block.face`` of an interface (block indices ``a``, ``b``, faces ``fa``, ``fb``)."""
    return f"{block_set.names[a]}.{fa.name} = {block_set.names[b]}.{fb.name}"


def face_index(block_set, interface) -> tuple[np.ndarray, np.ndarray]:
    """Flat (C-order) node indices of the interface's nodes in block a and, in the same order, in
    block b: shape (face nodes,) each."""
    shape_a, shape_b = block_set.node_shapes[interface.a], block_set.node_shapes[interface.b]
    fa, fb, T = interface.face_a, interface.face_b, interface.transform
    grids = np.meshgrid(*[np.arange(shape_a[axis]) for axis in fa.tangent_axes], indexing="ij")
    index_a = [None] * block_set.dim
    for axis, grid in zip(fa.tangent_axes, grids):
        index_a[axis] = grid.reshape(-1)
    index_a[fa.axis] = np.full(grids[0].size, (shape_a[fa.axis] - 1) * fa.side)
    index_b = [None] * block_set.dim
    for axis in fa.tangent_axes:
        target, sign = abs(T[axis]) - 1, int(np.sign(T[axis]))
        begin = 0 if sign > 0 else shape_b[target] - 1
        index_b[target] = begin + sign * index_a[axis]
    index_b[fb.axis] = np.full(grids[0].size, (shape_b[fb.axis] - 1) * fb.side)
    return np.ravel_multi_index(index_a, shape_a), np.ravel_multi_index(index_b, shape_b)


def interface_gaps(block_set, Xs) -> list[float]:
    """Largest distance between matching interface nodes, per interface."""
    gaps = []
    for interface in block_set.interfaces:
        index_a, index_b = face_index(block_set, interface)
        points_a = Xs[interface.a].reshape(-1, block_set.dim)[index_a]
        points_b = Xs[interface.b].reshape(-1, block_set.dim)[index_b]
        gaps.append(float(np.max(np.linalg.norm(points_a - points_b, axis=1))))
    return gaps


def unify_interfaces(block_set, Xs, tolerance: float = GAP_TOLERANCE) -> None:
    """Check that interface nodes coincide (GeometryError with the blocks, faces and largest gap
    otherwise) and make them identical: each block b takes block a's values (in place), in
    interface order, so a node shared by several blocks ends with one value everywhere."""
    for interface, gap in zip(block_set.interfaces, interface_gaps(block_set, Xs)):
        if gap > tolerance * block_set.length:
            raise GeometryError(
                f"geometry '{block_set.name}': the faces of interface "
                f"{interface_text(block_set, interface.a, interface.face_a, interface.b, interface.face_b)} do not coincide "
                f"(largest gap {gap:.3g})"
            )
    for b, a, target, source in _interface_copies(block_set):  # only the shared nodes move
        Xs[b][target] = Xs[a][source]


_COPIES = {}  # global_numbering's key -> _interface_copies' result


def _interface_copies(block_set) -> list[tuple]:
    """What ``unify_interfaces`` copies: (b, a, nodes of b, nodes of a), the node index tuples of
    block b's nodes whose first holder (in block order, ``global_numbering``) is block a's node."""
    key = (block_set.dim, tuple(block_set.node_shapes), block_set.interfaces)
    if key not in _COPIES:
        if len(_COPIES) > 8:
            _COPIES.clear()
        numbering, _ = global_numbering(block_set)
        sizes = [ids.size for ids in numbering]
        owner = np.repeat(np.arange(len(numbering)), sizes)  # the block of each position in block order
        local = np.concatenate([np.arange(size) for size in sizes])
        flat = np.concatenate([ids.reshape(-1) for ids in numbering])
        first = np.unique(flat, return_index=True)[1][flat]  # the first holder's position, per position
        shared = np.flatnonzero(first != np.arange(len(flat)))
        copies = []
        for b, a in np.unique(np.stack([owner[shared], owner[first[shared]]], axis=1), axis=0):
            moved = shared[(owner[shared] == b) & (owner[first[shared]] == a)]
            target = np.unravel_index(local[moved], numbering[b].shape)
            copies.append((int(b), int(a), target, np.unravel_index(local[first[moved]], numbering[a].shape)))
        _COPIES[key] = copies
    return _COPIES[key]


_NUMBERINGS = {}  # (dim, node shapes, interfaces) -> global_numbering's result: a set meshed again reuses it


def global_numbering(block_set) -> tuple[list[np.ndarray], int]:
    """Global node numbers (interface nodes merged): one int64 array of each block's node shape
    (read-only: shared by the sets of the same shapes and interfaces), and the number of unique
    nodes. Numbers follow the blocks' order, each block in C order."""
    key = (block_set.dim, tuple(block_set.node_shapes), block_set.interfaces)
    if key not in _NUMBERINGS:
        if len(_NUMBERINGS) > 8:
            _NUMBERINGS.clear()
        numbering, count = _numbering(block_set)
        for ids in numbering:
            ids.setflags(write=False)
        _NUMBERINGS[key] = (numbering, count)
    numbering, count = _NUMBERINGS[key]
    return list(numbering), count


def _numbering(block_set) -> tuple[list[np.ndarray], int]:
    shapes = block_set.node_shapes
    offsets = np.cumsum([0] + [int(np.prod(s)) for s in shapes])
    label = np.arange(offsets[-1])
    pairs = [(offsets[i.a] + ia, offsets[i.b] + ib) for i in block_set.interfaces for ia, ib in [face_index(block_set, i)]]
    if pairs:
        left = np.concatenate([p[0] for p in pairs])
        right = np.concatenate([p[1] for p in pairs])
        while True:  # each node ends labelled with the smallest number of the nodes it is glued to
            joined = label.copy()
            np.minimum.at(joined, left, label[right])
            np.minimum.at(joined, right, label[left])
            joined = joined[joined]
            if np.array_equal(joined, label):
                break
            label = joined
    unique, numbers = np.unique(label, return_inverse=True)
    return [numbers[offsets[i] : offsets[i + 1]].reshape(shape) for i, shape in enumerate(shapes)], len(unique)


def merged_mesh(block_set, Xs) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The block meshes as one unstructured mesh: (points (N, dim), cells (M, 8 or 4) in VTK
    corner order, block index of each cell (M,)). Cells follow the blocks' order."""

    numbering, count = global_numbering(block_set)
    points = np.empty((count, block_set.dim))
    cells, owner = [], []
    for index, (X, ids) in enumerate(zip(Xs, numbering)):
        points[ids.reshape(-1)] = X.reshape(-1, block_set.dim)
        local = cell_connectivity(X.shape[:-1])
        cells.append(ids.reshape(-1)[local])
        owner.append(np.full(len(local), index))
    return points, np.concatenate(cells), np.concatenate(owner)
