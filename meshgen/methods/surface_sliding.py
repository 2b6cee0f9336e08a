"""Nodes on projected faces (a topology file's ``project: SURFACE``) slide on their surface in the
elliptic solve of a block set (``meshgen.methods.elliptic.elliptic_blocks``; design notes §20).

A projected face's nodes lie on a curved surface (a cylinder, a torus, an STL or CAD face), where
the multigrid's planar rule (``meshgen.methods.sliding``) does not apply. Between multigrid solves
each such node moves to the surface's closest point to its neighbour one layer inside (the mean of
those neighbours where blocks give it several): the foot of the grid line leaving the wall, so the
lines meet the wall at right angles, as the planar rule makes them meet flat patches. Then the
interior is solved again with the moved nodes fixed. Rounds stop when no node moved by more than
``SURFACE_TOL`` of its local cell size, or after ``SURFACE_ROUNDS``.

A node slides only if every boundary face it lies on is projected onto the same surface: nodes
where a projected wall meets an inlet, another surface, a cyclic patch or a plane that slides by
its own rule stay where they are.
"""

from __future__ import annotations

import numpy as np

from meshgen.geometry import cube

__all__ = ["SURFACE_ROUNDS", "SURFACE_TOL", "slide_on_surfaces", "surface_sliding"]

SURFACE_ROUNDS = 6  # sliding rounds (each followed by a multigrid solve) at most
SURFACE_TOL = 1e-3  # stop once no node moves by more than this times its local cell size


def surface_sliding(block_set, numbering, count: int, planar=None) -> list[tuple]:
    """The sliding nodes of each surface: [(project, node numbers (P,), inner neighbour numbers
    (Q,), index of each inner neighbour's node in the node numbers (Q,))], empty when the set has no
    projected faces. ``planar``: ``planar_sliding``'s result (those nodes keep their own rule)."""
    if not getattr(block_set, "surfaces", None):
        return []
    dim = block_set.dim
    owner = np.full(count, -1, dtype=np.int64)  # the surface of a node's projected faces; -2: fixed
    glued = {(i.a, i.face_a) for i in block_set.interfaces} | {(i.b, i.face_b) for i in block_set.interfaces}
    projections = list(dict.fromkeys(block_set.surfaces.values()))  # each surface's map once
    pairs, rims = [], []
    for block, ids in enumerate(numbering):
        for face in cube.faces(dim):
            if (block, face) in glued:
                continue
            nodes = ids[face.node_index].reshape(-1)
            project = block_set.surfaces.get((block, face.name))
            if project is None:
                owner[nodes] = -2
                continue
            which = projections.index(project)
            mixed = (owner[nodes] != -1) & (owner[nodes] != which)
            owner[nodes] = np.where(mixed, -2, which)
            rim = np.ones(ids[face.node_index].shape, dtype=bool)
            rim[(slice(1, -1),) * (dim - 1)] = False
            rims.append(ids[face.node_index][rim].reshape(-1))
            inner_index = list(face.node_index)
            inner_index[face.axis] = -2 if face.side else 1
            pairs.append((which, nodes, ids[tuple(inner_index)].reshape(-1)))
    if planar is not None:
        owner[planar[0]] = -2
    for rim in rims:  # the faces' rims: block corners and edges on the surface stay
        owner[rim] = -2
    rules = []
    for which, project in enumerate(projections):
        chosen = [(n[owner[n] == which], i[owner[n] == which]) for w, n, i in pairs if w == which]
        nodes_all = np.concatenate([n for n, _ in chosen])
        if len(nodes_all):
            nodes, slot = np.unique(nodes_all, return_inverse=True)
            rules.append((project, nodes, np.concatenate([i for _, i in chosen]), slot.reshape(-1)))
    return rules


def slide_on_surfaces(rules: list[tuple], values: np.ndarray, sizes: np.ndarray) -> float:
    """Move every sliding node of ``rules`` (``surface_sliding``) in ``values`` (count, dim), in
    place, to its surface's closest point to the mean of its inner neighbours; returns the largest
    move relative to the node's local cell size (``sizes`` (count,))."""
    largest = 0.0
    for project, nodes, inner, slot in rules:
        mean = np.zeros((len(nodes), values.shape[1]))
        np.add.at(mean, slot, values[inner])
        mean /= np.bincount(slot, minlength=len(nodes))[:, None]
        moved = np.asarray(project(mean), dtype=float)
        largest = max(largest, float((np.linalg.norm(moved - values[nodes], axis=1) / sizes[nodes]).max(initial=0.0)))
        values[nodes] = moved
    return largest
