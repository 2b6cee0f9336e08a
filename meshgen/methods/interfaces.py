"""How the blocks of a block set meet, for the elliptic solver (``meshgen.methods.multigrid_set``):
each block padded with a halo layer on its interface faces, filled from the neighbour through the
interface's Transform, so that the interface nodes are interior nodes of every block holding them;
the junction nodes (where three or more blocks meet) and their rule.

Halo: the layer beyond an interface face of block a is block b's first layer of nodes inside,
turned into a's index frame. Its parametric coordinate across the face continues a's: b's first
cell scaled by the ratio of the blocks' mean lengths across the interface (``mean_length`` of the
start mesh), so that a cell of either block has the parametric size it has physically. The
Winslow equations are invariant under scaling one parametric axis, so at a block's own nodes this
is the block's own equation, and at an interface node it is the equation of the two blocks glued
into one along that axis. An interface node's value comes from block ``a`` of its interface (its
owner; tangential coordinates are a's).

Junctions: the nodes that neither a block's interior nor an interface face's interior holds and
that are on no patch (an O-grid core's corners: straight grid lines would give 90, 135 and 135
degrees there) satisfy the mean over the grid quadrilaterals at the node of the parallelogram
completion x_a + x_b - x_ab (in 3D the quads across the block edge the node is on; at a block
corner inside the set, where stacked O-grid sections or mitred pipes meet, the quads of the
block's three faces there), whose fixed point makes the cells around it as parallelogram-like as
their neighbours allow. A corner without a rule would keep its TFI place while its neighbours
move, and fold the cells round it.
"""

from __future__ import annotations

import numpy as np

from meshgen.geometry import cube
from meshgen.geometry.block_nodes import global_numbering
from meshgen.geometry.blocks import BlockSet, inverse_transform
from meshgen.methods.sliding import Rule

__all__ = [
    "Halo",
    "Layout",
    "JunctionRule",
    "faces_holding",
    "gather",
    "junction_nodes",
    "junction_stencil",
    "mean_length",
    "turn",
]


def turn(X: np.ndarray, transform) -> np.ndarray:
    """An array ``X`` with one block's node axes first in the index frame of the block the CGNS
    ``transform`` maps from (a view): that block's axis i is X's axis |transform[i]| - 1, reversed
    where negative."""
    axes = [abs(t) - 1 for t in transform]
    view = np.transpose(X, axes + list(range(len(transform), X.ndim)))
    for axis, t in enumerate(transform):
        if t < 0:
            view = np.flip(view, axis=axis)
    return view


def mean_length(X: np.ndarray, axis: int) -> float:
    """Mean over the grid lines along ``axis`` of the node array ``X`` (..., d) of their polyline length."""
    steps = np.linalg.norm(np.diff(X, axis=axis), axis=-1)
    return float(np.mean(np.sum(steps, axis=axis)))


def faces_holding(shape) -> np.ndarray:
    """(shape) int: on how many of the block's faces each node lies (0 inside, 1 on a face's
    interior, 2 or more on an edge or corner)."""
    count = np.zeros(shape, dtype=np.int64)
    for axis, n in enumerate(shape):
        index = [None] * len(shape)
        index[axis] = slice(None)
        line = np.zeros(n, dtype=np.int64)
        line[[0, -1]] = 1
        count += line[tuple(index)]
    return count


def junction_nodes(block_set: BlockSet) -> tuple[np.ndarray, list[np.ndarray], int]:
    """Global numbers of the nodes that neither a block's interior nor an interface face's interior
    holds and that are not on a patch (where three or more blocks meet), the global numbering and
    the node count."""
    numbering, count = global_numbering(block_set)
    held = np.zeros(count, dtype=bool)
    on_patch = np.zeros(count, dtype=bool)
    for (block, face_name), _patch in block_set.patches.items():
        on_patch[numbering[block][cube.face_named(face_name, block_set.dim).node_index]] = True
    for ids in numbering:
        held[ids[faces_holding(ids.shape) == 0]] = True
    for interface in block_set.interfaces:
        ids = numbering[interface.a]
        on_face = np.zeros(ids.shape, dtype=bool)
        on_face[interface.face_a.node_index] = True
        held[ids[on_face & (faces_holding(ids.shape) == 1)]] = True
    return np.flatnonzero(~held & ~on_patch), numbering, count


def junction_stencil(block_set: BlockSet, numbering, junctions):
    """For every grid quadrilateral at a junction node: (node, the quad's other corners (a, b, and
    the one opposite)): the parallelogram completion x = x_a + x_b - x_ab. In 3D the quads are
    those across the block edge the node lies on (in the layer of the node), so the rule acts in
    the section across the edge and keeps each node in its layer. Returns (nodes (Q,), others (Q, 3))."""
    count = max(int(ids.max()) for ids in numbering) + 1
    is_junction = np.zeros(count, dtype=bool)
    is_junction[junctions] = True
    nodes, others = [], []
    dim = block_set.dim
    for ids in numbering:
        local = np.argwhere(is_junction[ids])
        if len(local) == 0:
            continue
        shape = np.array(ids.shape)
        free = ~((local == 0) | (local == shape - 1))  # axes along which the node is inside the block
        cases = [(None, [0, 1])] if dim == 2 else [(axis, [a for a in range(3) if a != axis]) for axis in range(3)]
        if dim == 3:  # a block corner inside the set (stacked O-grid sections): the quads of the block's 3 faces there
            cases += [("corner", plane) for plane in ([1, 2], [0, 2], [0, 1])]
        for edge_axis, plane in cases:
            if edge_axis is None:
                rows = np.arange(len(local))
            elif edge_axis == "corner":
                rows = np.flatnonzero(free.sum(axis=1) == 0)
            else:  # on a block edge along edge_axis: the quads across the edge, in the node's layer
                rows = np.flatnonzero(free[:, edge_axis] & (free.sum(axis=1) == 1))
            for step_a in (-1, 1):
                for step_b in (-1, 1):
                    a, b = local[rows].copy(), local[rows].copy()
                    a[:, plane[0]] += step_a
                    b[:, plane[1]] += step_b
                    ab = a.copy()
                    ab[:, plane[1]] += step_b
                    inside = np.all((ab >= 0) & (ab < shape), axis=1)
                    nodes.append(ids[tuple(local[rows][inside].T)])
                    others.append(np.stack([ids[tuple(c[inside].T)] for c in (a, b, ab)], axis=1))
    nodes = np.concatenate(nodes) if nodes else np.zeros(0, dtype=int)
    others = np.concatenate(others) if others else np.zeros((0, 3), dtype=int)
    return nodes, others


class JunctionRule(Rule):
    """The junctions' equations (``junction_stencil``): a term per quad, the parallelogram
    completion x_a + x_b - x_ab minus the node; a second difference (power 2)."""

    def __init__(self, stencil, values: np.ndarray):
        nodes, others = stencil
        super().__init__(nodes, (others,), 2, values)

    def offsets(self, values: np.ndarray) -> np.ndarray:
        (others,) = self.terms
        return values[others[:, 0]] + values[others[:, 1]] - values[others[:, 2]] - values[self.rows]


def gather(Xs, numbering, count) -> np.ndarray:
    """The unique nodes (count, dim) of the blocks' node arrays (the last block holding a node gives it)."""
    values = np.empty((count, Xs[0].shape[-1]))
    for X, ids in zip(Xs, numbering):
        values[ids.reshape(-1)] = X.reshape(-1, X.shape[-1])
    return values


class Halo:
    """The blocks of a block set on one grid, each padded with a halo layer on its interface faces
    and a ghost layer on its other faces (copies of the face's nodes: the line relaxation reaches
    the faces' sliding nodes through it, ``meshgen.methods.multigrid_set``), so that a block's own
    nodes are its padded array's interior.

    ``block_set``: the set at this grid's parametric coordinates; ``lengths``: per interface, the
    mean lengths (a's, b's) across it. Attributes, per block: ``pad`` (per axis, (before, after)
    layers, all 1), ``ghost_faces`` (the faces with a ghost layer), ``padded_coords`` (1D parametric coordinates per axis, halo included),
    ``padded_ids`` (global node numbers of the padded array; the halo's corners, which no solved
    node's stencil reaches, hold a neighbouring node's), ``frozen`` (bool, the padded array's
    interior nodes the Winslow equations do not move: block edges and corners), ``writes``
    ((flat indices, global numbers) of the nodes the block gives: all but the interface faces it
    does not own); and ``numbering``, ``count``."""

    def __init__(self, block_set: BlockSet, lengths):
        self.block_set = block_set
        self.numbering, self.count = global_numbering(block_set)
        dim = block_set.dim
        blocks = range(len(block_set.coords))
        self.pad = [[[0, 0] for _ in range(dim)] for _ in blocks]
        self.padded_coords = [[np.asarray(t, dtype=float) for t in c] for c in block_set.coords]
        halos = [[] for _ in blocks]  # per block: (face, global ids of the halo layer)
        for interface, (length_a, length_b) in zip(block_set.interfaces, lengths):
            for a, b, face_a, face_b, inverse in (
                (interface.a, interface.b, interface.face_a, interface.face_b, False),
                (interface.b, interface.a, interface.face_b, interface.face_a, True),
            ):
                ratio = (length_a / length_b) if inverse else (length_b / length_a)
                t_b = np.asarray(block_set.coords[b][face_b.axis], dtype=float)
                first = t_b[-1] - t_b[-2] if face_b.side else t_b[1] - t_b[0]
                ids_b = self.numbering[b]
                inner = np.take(ids_b, -2 if face_b.side else 1, axis=face_b.axis)
                layer = self._in_frame(block_set, interface, inner, face_a, face_b, inverse)
                t = self.padded_coords[a][face_a.axis]
                if face_a.side:
                    self.padded_coords[a][face_a.axis] = np.append(t, t[-1] + ratio * first)
                else:
                    self.padded_coords[a][face_a.axis] = np.insert(t, 0, t[0] - ratio * first)
                self.pad[a][face_a.axis][face_a.side] = 1
                halos[a].append((face_a, layer))
        self.ghost_faces = [[] for _ in blocks]  # per block: its faces on patches, padded with a ghost layer
        for block in blocks:
            for axis in range(dim):
                for side in (0, 1):
                    if self.pad[block][axis][side]:
                        continue
                    t = self.padded_coords[block][axis]
                    self.padded_coords[block][axis] = (
                        np.append(t, 2 * t[-1] - t[-2]) if side else np.insert(t, 0, 2 * t[0] - t[1])
                    )
                    self.pad[block][axis][side] = 1
                    self.ghost_faces[block].append(cube.Face(dim, axis, side))
        self.padded_ids, self.frozen, self.writes = [], [], []
        owned_faces = [[] for _ in blocks]
        for interface in block_set.interfaces:
            owned_faces[interface.b].append(interface.face_b)  # b does not give these
        for block, ids in enumerate(self.numbering):
            padded = np.pad(ids, self.pad[block], mode="edge")
            inside = tuple(slice(p[0], p[0] + n) for p, n in zip(self.pad[block], ids.shape))
            for face, layer in halos[block]:
                index = list(inside)
                index[face.axis] = -1 if face.side else 0
                padded[tuple(index)] = layer
            self.padded_ids.append(padded)
            holding = faces_holding(ids.shape)
            frozen = np.ones(padded.shape, dtype=bool)
            frozen[inside] = holding >= 2
            self.frozen.append(np.ascontiguousarray(frozen[(slice(1, -1),) * dim]))
            gives = np.ones(ids.shape, dtype=bool)
            for face in owned_faces[block]:
                on_face = np.zeros(ids.shape, dtype=bool)
                on_face[face.node_index] = True
                gives &= ~(on_face & (holding == 1))
            flat = np.flatnonzero(gives)
            self.writes.append((flat, ids.reshape(-1)[flat]))

    @staticmethod
    def _in_frame(block_set, interface, layer_b, face_a, face_b, inverse):
        """Block b's layer (b's face shape, its normal axis dropped) in block a's index frame at a's
        face, for the interface seen from a (``inverse``: a is the interface's own b)."""
        full = np.expand_dims(layer_b, face_b.axis)  # b's node axes, 1 across
        T = inverse_transform(interface.transform) if inverse else interface.transform
        return turn(full, T)[face_a.node_index]

    def padded(self, values: np.ndarray) -> list[np.ndarray]:
        """Each block's padded component-first array (dim, ...) from the unique nodes (count, dim)."""
        return [np.ascontiguousarray(np.moveaxis(values[ids], -1, 0)) for ids in self.padded_ids]

    def inside(self, block: int) -> tuple:
        """Index of the block's own nodes in its padded component-first array."""
        shape = self.numbering[block].shape
        return (slice(None),) + tuple(slice(p[0], p[0] + n) for p, n in zip(self.pad[block], shape))

    def unique(self, arrays, out: np.ndarray | None = None) -> np.ndarray:
        """The unique nodes (count, dim) from the blocks' own component-first arrays (dim, ...)
        (unpadded), each node from the block that owns it; ``out``: start from (and fill) it."""
        values = np.empty((self.count, arrays[0].shape[0])) if out is None else out
        for R, (flat, ids) in zip(arrays, self.writes):
            values[ids] = R.reshape(R.shape[0], -1)[:, flat].T
        return values


class Layout:
    """The padded blocks of a ``Halo`` as one flat buffer, so that moving values between the
    blocks is one array operation: block b's padded component-first array (dim, ...) is the
    contiguous slice ``[offset_b, offset_b + dim n_b)`` of the buffer (n_b: its padded node count).

    Every unique node has one owner position (the block that gives it in ``Halo.unique``); the
    other copies of it (halo and ghost layers, a non-owner's interface face, the block edges that
    several blocks hold) are ``targets`` filled from ``sources`` by ``exchange``: after a
    relaxation sweep only these, about the blocks' surfaces, move, not the whole mesh."""

    def __init__(self, halo: Halo, dim: int):
        self.dim = dim
        self.shapes = [ids.shape for ids in halo.padded_ids]
        sizes = [ids.size for ids in halo.padded_ids]
        self.offsets = np.concatenate([[0], np.cumsum([dim * n for n in sizes])])
        components = np.arange(dim)[:, None]
        self.positions = np.concatenate(  # (dim, all padded nodes): each padded node's positions
            [offset + components * n + np.arange(n) for offset, n in zip(self.offsets, sizes)], axis=1
        )
        self.ids = np.concatenate([ids.reshape(-1) for ids in halo.padded_ids])
        self.owner = np.empty((dim, halo.count), dtype=np.int64)  # the owner position of each unique node
        for block, (flat, ids) in enumerate(halo.writes):  # later blocks override, as in Halo.unique
            own = np.unravel_index(flat, halo.numbering[block].shape)
            padded = np.ravel_multi_index(tuple(i + p[0] for i, p in zip(own, halo.pad[block])), self.shapes[block])
            self.owner[:, ids] = self.offsets[block] + components * sizes[block] + padded
        copies = self.positions[0] != self.owner[0, self.ids]
        self.targets = self.positions[:, copies].reshape(-1)
        self.sources = self.owner[:, self.ids[copies]].reshape(-1)
        self.size = int(self.offsets[-1])

    def load(self, values: np.ndarray) -> np.ndarray:
        """The buffer from the unique nodes (count, dim)."""
        buffer = np.empty(self.size)
        buffer[self.positions] = values[self.ids].T
        return buffer

    def views(self, buffer: np.ndarray) -> list[np.ndarray]:
        """Each block's padded component-first array (dim, ...): a view of the buffer."""
        return [
            buffer[start:stop].reshape((self.dim,) + shape)
            for start, stop, shape in zip(self.offsets[:-1], self.offsets[1:], self.shapes)
        ]

    def unique(self, buffer: np.ndarray) -> np.ndarray:
        """The unique nodes (count, dim) from their owners' positions."""
        return buffer[self.owner].T.copy()

    def read(self, buffer: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """The nodes ``ids`` (len, dim) from their owners' positions."""
        return buffer[self.owner[:, ids]].T

    def write(self, buffer: np.ndarray, ids: np.ndarray, values: np.ndarray) -> None:
        """Set the owners' positions of the nodes ``ids`` to ``values`` (len, dim); ``exchange``
        hands them on to the copies."""
        buffer[self.owner[:, ids]] = values.T

    def exchange(self, buffer: np.ndarray) -> None:
        """Every copy of a node from its owner (in place)."""
        buffer[self.targets] = buffer[self.sources]
