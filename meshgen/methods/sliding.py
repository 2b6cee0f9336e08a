"""Boundary nodes of a block set that move by their own rules in the elliptic solver
(``meshgen.methods.elliptic.elliptic_blocks``), as equations with a residual on every multigrid
level (``meshgen.methods.multigrid_set``):

- nodes on flat patches only, in one plane, slide in it to the projection of their neighbour one
  layer inside; in 3D nodes on two planes that meet in a line (a channel's edge) slide along it
  the same way: grid lines meet flat inlets, outlets and straight walls at right angles, and a
  straight extrusion (the pipe, the 3D channel) is meshed as the extrusion of its section's mesh
  (``planar_sliding``, ``SlideRule``). Nodes on curved patches, on a corner of two lines (2D)
  or on three planes stay where the TFI put them, and so do a plane's nodes where a curved patch
  meets it obliquely (``OBLIQUE``: a tapered pipe's caps) and the nodes of cyclic patches (they
  keep matching their pair's: ``meshgen.geometry.cyclic``);
- the local cell size of every node (``local_cell_sizes``), the unit of the stopping rule.
"""

from __future__ import annotations

import numpy as np

from meshgen.geometry import cube
from meshgen.geometry.blocks import BlockSet

__all__ = ["OBLIQUE", "Rule", "SlideRule", "distinct_planes", "local_cell_sizes", "planar_sliding"]

# A flat patch whose rim on a curved patch leaves it at a grid-line angle with cosine below this
# (about 8 degrees off its normal: a tapered pipe's inlet) does not slide: sliding would push its
# nodes towards the right angle that the fixed rim cannot give, and fold the cells at the rim.
OBLIQUE = 0.99


def planar_sliding(block_set: BlockSet, Xs, numbering, count, tolerance: float = 1e-12):
    """The boundary nodes that slide: those on flat patch faces only (all a face's nodes within
    ``tolerance`` times the characteristic length of a plane) whose faces lie in one plane (they
    slide in it), or in 3D in two planes that meet in a line (they slide along it: a channel's edge
    where a flat wall meets a flat inlet or cap). A node on a curved patch, on a corner of two lines
    (2D) or on three planes stays put.
    Returns per (node, inner neighbour) pair: the node's number (P,), the neighbour's (P,) and the
    projector (P, dim, dim) onto the node's plane or line's direction(s); None when no node slides."""
    dim = block_set.dim
    curved = np.zeros(count, dtype=bool)
    records = []  # (node ids, inner neighbour ids, centre, normal) per flat patch face
    for (block, face_name), (_, kind) in block_set.patches.items():
        face = cube.face_named(face_name, dim)
        ids = numbering[block][face.node_index].reshape(-1)
        if kind == "cyclic":  # its nodes stay where the TFI put them: sliding would part them from their pair's
            curved[ids] = True
            continue
        points = Xs[block][face.node_index].reshape(-1, dim)
        centre = points.mean(axis=0)
        _, singular, vt = np.linalg.svd(points - centre, full_matrices=False)
        if singular[-1] > tolerance * block_set.length * np.sqrt(len(points)):
            curved[ids] = True
            continue
        inner_index = list(face.node_index)
        inner_index[face.axis] = -2 if face.side else 1
        normal = np.where(np.abs(vt[-1]) < 1e-12, 0.0, vt[-1])  # an axis-aligned plane: its coordinate kept exactly
        records.append((ids, numbering[block][tuple(inner_index)].reshape(-1), centre, normal / np.linalg.norm(normal)))
    planes, normals = distinct_planes([(centre, normal) for _, _, centre, normal in records], block_set.length)
    on_plane = np.zeros((count, len(normals)), dtype=bool)
    for (ids, *_), plane in zip(records, planes):
        on_plane[ids, plane] = True
    kinds = on_plane.sum(axis=1)
    free = ~curved & ((kinds == 1) | ((kinds == 2) & (dim == 3)))
    values = np.zeros((count, dim))
    for block, X in enumerate(Xs):
        values[numbering[block].reshape(-1)] = X.reshape(-1, dim)
    for (ids, inside, _, normal), plane in zip(records, planes):
        rim = curved[ids]  # the face's nodes on a curved patch: they stay, so the plane's grid lines must meet them
        offsets = values[inside[rim]] - values[ids[rim]]
        along = np.abs(offsets @ normal) / np.maximum(np.linalg.norm(offsets, axis=1), 1e-300)
        if len(along) and along.min() < OBLIQUE:
            free[on_plane[:, plane]] = False  # a curved wall meets the plane obliquely: right angles cannot hold
    nodes, inner, projectors = [], [], []
    for ids, inside, _, normal in records:
        keep = free[ids]
        ids, inside = ids[keep], inside[keep]
        projector = np.broadcast_to(np.eye(dim) - np.outer(normal, normal), (len(ids), dim, dim)).copy()
        two = kinds[ids] == 2
        if two.any():  # the line where the node's two planes meet
            pair = np.nonzero(on_plane[ids[two]])[1].reshape(-1, 2)
            direction = np.cross(normals[pair[:, 0]], normals[pair[:, 1]])
            direction /= np.linalg.norm(direction, axis=1, keepdims=True)
            projector[two] = np.einsum("pi,pj->pij", direction, direction)
        nodes.append(ids)
        inner.append(inside)
        projectors.append(projector)
    if not sum(len(n) for n in nodes):
        return None
    return np.concatenate(nodes), np.concatenate(inner), np.concatenate(projectors)


def distinct_planes(planes, length: float, tolerance: float = 1e-9) -> tuple[list[int], np.ndarray]:
    """A plane number per (centre, unit normal), equal for planes that coincide to ``tolerance``,
    and the unit normals (P, d) of the distinct planes (a loop over the patch faces, not nodes)."""
    numbers, kept = [], []
    for centre, normal in planes:
        for number, (c, n) in enumerate(kept):
            if abs(abs(n @ normal) - 1.0) < tolerance and abs((centre - c) @ n) < tolerance * length:
                numbers.append(number)
                break
        else:
            numbers.append(len(kept))
            kept.append((centre, normal))
    return numbers, np.array([n for _, n in kept]) if kept else np.zeros((0, 3))


class Rule:
    """A boundary rule's equations at its nodes, as a residual that is zero at the rule's fixed
    point and whose Jacobi step moves a node by the residual itself: per node (unique,
    ascending, ``nodes``) the mean over its terms of a term's offset. ``power``: the rule's residual
    scales as a cell's size to this power (1: a difference of neighbours, 2: a second difference);
    ``spacing``: per node its neighbours' mean distance on the start mesh, by which a multigrid
    level's residual is compared with the next coarser one's."""

    def __init__(self, rows: np.ndarray, terms, power: int, values: np.ndarray):
        self.nodes, self.slot = np.unique(rows, return_inverse=True)
        self.rows, self.terms, self.power = rows, terms, power
        self.count = np.bincount(self.slot, minlength=len(self.nodes)).astype(float)
        distance = np.linalg.norm(values[terms[0][:, 0]] - values[rows], axis=-1)
        self.spacing = np.bincount(self.slot, weights=distance, minlength=len(self.nodes)) / self.count

    def offsets(self, values: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def residual(self, values: np.ndarray) -> np.ndarray:
        """(nodes, dim): the mean of the terms' offsets at each node."""
        offsets = self.offsets(values)
        return (
            np.stack(
                [np.bincount(self.slot, weights=offsets[:, c], minlength=len(self.nodes)) for c in range(values.shape[1])], axis=1
            )
            / self.count[:, None]
        )


class SlideRule(Rule):
    """The sliding nodes of ``planar_sliding``: a term per (node, inner neighbour) pair, the
    neighbour's offset projected onto the node's plane or line, P (x_inner - x_node); zero when
    grid lines meet the patch at right angles. The step moves the node to the mean of its projected
    neighbours."""

    def __init__(self, sliding, values: np.ndarray):
        nodes, inner, projector = sliding
        super().__init__(nodes, (inner[:, None], projector), 1, values)

    def offsets(self, values: np.ndarray) -> np.ndarray:
        inner, projector = self.terms
        return np.einsum("pij,pj->pi", projector, values[inner[:, 0]] - values[self.rows])


def local_cell_sizes(block_set: BlockSet, Xs, numbering, count) -> np.ndarray:
    """(count,) for every unique node, its shortest grid edge over every block holding it."""
    sizes = np.full(count, np.inf)
    for X, ids in zip(Xs, numbering):
        shortest = np.full(X.shape[:-1], np.inf)
        for axis in range(block_set.dim):
            edges = np.linalg.norm(np.diff(X, axis=axis), axis=-1)
            lower = [slice(None)] * block_set.dim
            upper = [slice(None)] * block_set.dim
            lower[axis], upper[axis] = slice(0, -1), slice(1, None)
            shortest[tuple(lower)] = np.minimum(shortest[tuple(lower)], edges)
            shortest[tuple(upper)] = np.minimum(shortest[tuple(upper)], edges)
        np.minimum.at(sizes, ids.reshape(-1), shortest.reshape(-1))
    return sizes
