"""Elliptic (Winslow) meshes of block sets: the interface nodes are solved as interior nodes of the
whole mesh (design notes §11, §20), starting from the multi-block TFI.

Method: Schwarz sweeps over the interfaces. For each interface, its two blocks are glued along it
into one structured block (the second block's node array turned into the first one's index frame
by the interface's Transform), whose interior, interface nodes included, ``meshgen.methods.elliptic``'s
multigrid Winslow cycles relax with the glued block's boundary fixed (the hierarchy of each glued
block is built once). Every block takes part in the solves of all its interfaces, so each sweep
passes information across the whole set. The glued block's parametric coordinate across the
interface runs through the first block's nodes, then the second's, each block's part scaled by
the block's mean length along that axis, so that a cell of either block has the parametric size
it has physically. Anderson mixing of the sweeps (``meshgen.methods.elliptic.AndersonMixing``).

After each sweep, two kinds of nodes that no glued block holds inside move by their own rules:

- junctions, where three or more blocks meet (an O-grid core's corners: straight grid lines would
  give 90, 135 and 135 degrees there): the mean over the grid quadrilaterals at the node of the
  parallelogram completion x_a + x_b - x_ab (in 3D the quads across the block edge the node is
  on), whose fixed point makes the cells around it as parallelogram-like as their neighbours allow;
- nodes on flat patches only, in one plane, slide in it to the projection of their neighbour one
  layer inside; in 3D nodes on two planes that meet in a line (a channel's edge) slide along it the
  same way: grid lines meet flat inlets, outlets and straight walls at right angles, and a straight
  extrusion (the pipe, the 3D channel) is meshed as the extrusion of its section's mesh.

Nodes on curved patches, on a corner of two lines (2D) or on three planes stay where the TFI put them.

Stopping rule: a sweep's update is the largest node displacement relative to the node's local
cell size (its shortest grid edge in the TFI start), the measure a flow solver feels: a node that
moves by a fraction of its cells' size changes their face areas and volumes by that fraction, so
a straight extrusion (the pipe) is an extrusion to that relative accuracy at every resolution.
"""

from __future__ import annotations

import time

import numpy as np

from meshgen.geometry import cube
from meshgen.geometry.blocks import BlockSet, global_numbering, tfi_blocks
from meshgen.methods.elliptic import DEFAULT_TOL, AndersonMixing, hierarchy, v_cycle
from meshgen.methods.winslow import component_array, node_array, stencils, winslow_operator

__all__ = ["elliptic_blocks", "glue", "junction_nodes", "local_cell_sizes", "mean_length"]

MAX_SWEEPS = 200  # Schwarz sweeps over all interfaces
# Multigrid V-cycles per glued block and sweep, by dimension: the 3D pipe at 32 x 16 x 4 takes 91
# sweeps with 1 and 22 with 2; the 2D DFG channel 33 sweeps either way (its sliding walls set the pace).
# In 3D the glued blocks' cycles run the compiled kernels whatever their size: the sweeps repeat
# them a few hundred times, which repays loading numba even for the smallest pipe (NumPy 1.9 s,
# kernels 0.13 s at 4 x 2 x 3).
INNER_CYCLES = {2: 1, 3: 2}
ANDERSON_DEPTH = 10  # sweeps remembered by the Anderson mixing of the sweeps
RELAX_JUNCTIONS = True


def _turned(block_set: BlockSet, interface, X: np.ndarray) -> tuple[np.ndarray, list]:
    """Block b's array ``X`` (or any array with b's node axes first) in block a's index frame:
    (array, per a-axis (b axis, sign))."""
    T = interface.transform
    axes = [abs(t) - 1 for t in T]
    turned = np.transpose(X, axes + list(range(block_set.dim, X.ndim)))
    for axis, t in enumerate(T):
        if t < 0:
            turned = np.flip(turned, axis=axis)
    return turned, [(abs(t) - 1, int(np.sign(t))) for t in T]


def mean_length(X: np.ndarray, axis: int) -> float:
    """Mean over the grid lines along ``axis`` of the node array ``X`` (..., d) of their polyline length."""
    steps = np.linalg.norm(np.diff(X, axis=axis), axis=-1)
    return float(np.mean(np.sum(steps, axis=axis)))


def glue(block_set: BlockSet, Xs, interface) -> tuple[np.ndarray, list, tuple, tuple]:
    """The two blocks of ``interface`` as one structured block in block a's index frame:
    (node array, parametric coordinates per axis, index of block a's part, index of block b's
    part in the glued array); block b's part is the turned array of ``_turned``."""
    a, b = interface.a, interface.b
    face = interface.face_a
    A = Xs[a]
    B, mapping = _turned(block_set, interface, Xs[b])
    normal = face.axis
    coords_a = block_set.coords[a][normal]
    b_axis, b_sign = mapping[normal]
    coords_b = block_set.coords[b][b_axis]
    if b_sign < 0:
        coords_b = 1.0 - coords_b[::-1]
    length_a, length_b = mean_length(A, normal), mean_length(B, normal)
    n_a, n_b = A.shape[normal], B.shape[normal]
    if face.side == 1:
        glued = np.concatenate([A, np.take(B, range(1, n_b), axis=normal)], axis=normal)
        along = np.concatenate([length_a * coords_a, length_a + length_b * coords_b[1:]])
        part_a = tuple(slice(0, n_a) if d == normal else slice(None) for d in range(block_set.dim))
        part_b = tuple(slice(n_a - 1, None) if d == normal else slice(None) for d in range(block_set.dim))
    else:
        glued = np.concatenate([np.take(B, range(0, n_b - 1), axis=normal), A], axis=normal)
        along = np.concatenate([length_b * coords_b[:-1], length_b + length_a * coords_a])
        part_b = tuple(slice(0, n_b) if d == normal else slice(None) for d in range(block_set.dim))
        part_a = tuple(slice(n_b - 1, None) if d == normal else slice(None) for d in range(block_set.dim))
    coords = [np.asarray(t, dtype=float) for t in block_set.coords[a]]
    coords[normal] = (along - along[0]) / (along[-1] - along[0])
    return glued, coords, part_a, part_b


def _scatter(block_set: BlockSet, Xs, interface, glued, part_a, part_b) -> None:
    """Write the glued array back into both blocks (b's part turned back to b's frame)."""
    Xs[interface.a][...] = glued[part_a]
    view, _ = _turned(block_set, interface, Xs[interface.b])  # a view: writing it writes Xs[b]
    view[...] = glued[part_b]


def junction_nodes(block_set: BlockSet) -> tuple[np.ndarray, list[np.ndarray], int]:
    """Global numbers of the nodes that no glued block holds inside and that are not on a patch
    (where three or more blocks meet), the global numbering and the node count."""
    numbering, count = global_numbering(block_set)
    held = np.zeros(count, dtype=bool)
    on_patch = np.zeros(count, dtype=bool)
    for (block, face_name), _patch in block_set.patches.items():
        on_patch[numbering[block][cube.face_named(face_name, block_set.dim).node_index]] = True
    interior = (slice(1, -1),) * block_set.dim
    for interface in block_set.interfaces:
        ids_a = numbering[interface.a]
        ids_b, _ = _turned(block_set, interface, numbering[interface.b])
        normal = interface.face_a.axis
        if interface.face_a.side == 1:
            glued_ids = np.concatenate([ids_a, np.take(ids_b, range(1, ids_b.shape[normal]), axis=normal)], axis=normal)
        else:
            glued_ids = np.concatenate([np.take(ids_b, range(0, ids_b.shape[normal] - 1), axis=normal), ids_a], axis=normal)
        held[glued_ids[interior]] = True
    for ids in numbering:  # a block's own interior (a block with no interface)
        held[ids[interior]] = True
    return np.flatnonzero(~held & ~on_patch), numbering, count


def _relax_junctions(block_set: BlockSet, Xs, junctions, numbering, stencil) -> None:
    """Move each junction node to the mean, over its cells, of the position that would make each
    cell a parallelepiped (parallelogram) given the cell's other corners (in every block copy)."""
    if len(junctions) == 0:
        return
    count = max(int(ids.max()) for ids in numbering) + 1
    values = _gather(Xs, numbering, count)
    node, others, signs = stencil
    predicted = np.einsum("pc,pcd->pd", signs, values[others])
    total = np.zeros((count, block_set.dim))
    hits = np.zeros(count)
    np.add.at(total, node, predicted)
    np.add.at(hits, node, 1.0)
    values[junctions] = total[junctions] / hits[junctions, None]
    is_junction = np.zeros(count, dtype=bool)
    is_junction[junctions] = True
    for X, ids in zip(Xs, numbering):
        mask = is_junction[ids]
        X[mask] = values[ids[mask]]


def planar_sliding(block_set: BlockSet, Xs, numbering, count, tolerance: float = 1e-12):
    """The boundary nodes that slide: those on flat patch faces only (all a face's nodes within
    ``tolerance`` times the characteristic length of a plane) whose faces lie in one plane (they
    slide in it), or in 3D in two planes that meet in a line (they slide along it: a channel's edge
    where a flat wall meets a flat inlet or cap). A node on a curved patch, on a corner of two lines
    (2D) or on three planes stays put.
    Returns per (node, inner neighbour) pair: the node's number (P,), the neighbour's (P,) and the
    projector (P, dim, dim) onto the node's plane or line's direction(s)."""
    dim = block_set.dim
    curved = np.zeros(count, dtype=bool)
    records = []  # (node ids, inner neighbour ids, centre, normal) per flat patch face
    for (block, face_name), _ in block_set.patches.items():
        face = cube.face_named(face_name, dim)
        ids = numbering[block][face.node_index].reshape(-1)
        points = Xs[block][face.node_index].reshape(-1, dim)
        centre = points.mean(axis=0)
        _, singular, vt = np.linalg.svd(points - centre, full_matrices=False)
        if singular[-1] > tolerance * block_set.length * np.sqrt(len(points)):
            curved[ids] = True
            continue
        inner_index = list(face.node_index)
        inner_index[face.axis] = -2 if face.side else 1
        records.append((ids, numbering[block][tuple(inner_index)].reshape(-1), centre, vt[-1]))
    planes, normals = _distinct_planes([(centre, normal) for _, _, centre, normal in records], block_set.length)
    on_plane = np.zeros((count, len(normals)), dtype=bool)
    for (ids, *_), plane in zip(records, planes):
        on_plane[ids, plane] = True
    kinds = on_plane.sum(axis=1)
    free = ~curved & ((kinds == 1) | ((kinds == 2) & (dim == 3)))
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


def _distinct_planes(planes, length: float, tolerance: float = 1e-9) -> tuple[list[int], np.ndarray]:
    """A plane number per (centre, unit normal), equal for planes that coincide to ``tolerance``,
    and the unit normals (P, d) of the distinct planes."""
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


def _slide(block_set: BlockSet, Xs, numbering, count, sliding) -> None:
    """Each sliding node to the mean of its inner neighbours projected onto its plane or line: grid
    lines meet the flat patches at right angles (a Neumann condition)."""
    if sliding is None:
        return
    nodes, inner, projector = sliding
    values = _gather(Xs, numbering, count)
    point = values[nodes]  # on the node's plane or line, where the TFI put it and sliding keeps it
    projected = point + np.einsum("pij,pj->pi", projector, values[inner] - point)
    total = np.zeros((count, block_set.dim))
    hits = np.zeros(count)
    np.add.at(total, nodes, projected)
    np.add.at(hits, nodes, 1.0)
    moved = np.flatnonzero(hits)
    values[moved] = total[moved] / hits[moved, None]
    is_moved = np.zeros(count, dtype=bool)
    is_moved[moved] = True
    for X, ids in zip(Xs, numbering):
        mask = is_moved[ids]
        X[mask] = values[ids[mask]]


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


def _gather(Xs, numbering, count) -> np.ndarray:
    """The unique nodes (count, dim) of the blocks' arrays."""
    values = np.empty((count, Xs[0].shape[-1]))
    for X, ids in zip(Xs, numbering):
        values[ids.reshape(-1)] = X.reshape(-1, X.shape[-1])
    return values


def _junction_stencil(block_set: BlockSet, numbering, junctions):
    """For every grid quadrilateral at a junction node: (node, the quad's other corners (a, b, and
    the one opposite), signs (1, 1, -1)): the parallelogram completion x = x_a + x_b - x_ab. In 3D
    the quads are those across the block edge the node lies on (in the layer of the node), so the
    rule acts in the section across the edge and keeps each node in its layer."""
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
        for edge_axis in range(dim) if dim == 3 else [None]:
            if edge_axis is None:
                rows, plane = np.arange(len(local)), [0, 1]
            else:  # on a block edge along edge_axis: the quads across the edge, in the node's layer
                rows = np.flatnonzero(free[:, edge_axis] & (free.sum(axis=1) == 1))
                plane = [axis for axis in range(dim) if axis != edge_axis]
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
    signs = np.broadcast_to([1.0, 1.0, -1.0], (len(nodes), 3))
    return nodes, others, signs


def elliptic_blocks(
    block_set: BlockSet,
    tol: float | None = None,
    max_iter: int | None = None,
    progress=None,
    slide: bool = True,
    initial=None,
):
    """Multi-block Winslow mesh of ``block_set``: (list of node arrays, one per block, interface
    nodes identical in every block; info dict as ``meshgen.methods.elliptic.solve_winslow``'s, with
    ``sweeps``). ``tol``: stop when a sweep moves no node by more than ``tol`` times its local cell
    size (``local_cell_sizes``; ``final_update`` is in that unit); ``max_iter``: most sweeps;
    ``slide`` (default on): nodes on flat patches (a pipe's inlet, a channel's straight walls)
    slide in their plane, or along the line where two meet, so that grid lines meet them at right
    angles (``planar_sliding``), else every boundary node stays where the TFI put it. ``initial``: the node arrays to start from (conforming, on the boundary: a
    network's corrected mesh; copied), else the TFI."""
    tol = DEFAULT_TOL if tol is None else tol
    max_sweeps = MAX_SWEEPS if max_iter is None else max_iter
    start = time.perf_counter()
    Xs = tfi_blocks(block_set) if initial is None else [np.array(X, dtype=float) for X in initial]
    if min(min(shape) for shape in block_set.node_shapes) < 3:
        return Xs, {"sweeps": 0, "converged": True, "note": "a block has one cell across an axis: the TFI mesh is the mesh"}
    junctions, numbering, count = junction_nodes(block_set)
    stencil = _junction_stencil(block_set, numbering, junctions)
    sizes = local_cell_sizes(block_set, Xs, numbering, count)
    levels = []  # per interface: the multigrid hierarchy of its glued block (coordinates do not change)
    for interface in block_set.interfaces:
        glued, coords, _, _ = glue(block_set, Xs, interface)
        _, axial = winslow_operator(component_array(glued), stencils(coords))
        levels.append(hierarchy(coords, [np.median(c) for c in axial], compiled=block_set.dim == 3))
    sliding = planar_sliding(block_set, Xs, numbering, count) if slide else None
    mixing = AndersonMixing(ANDERSON_DEPTH)
    update, sweeps, first = np.inf, 0, None
    state = _gather(Xs, numbering, count)
    while sweeps < max_sweeps:
        before = state
        for interface, hierarchy_of in zip(block_set.interfaces, levels):
            glued, _, part_a, part_b = glue(block_set, Xs, interface)
            R = component_array(glued)
            for _ in range(INNER_CYCLES[block_set.dim]):
                v_cycle(hierarchy_of, 0, R, None)
            _scatter(block_set, Xs, interface, node_array(R), part_a, part_b)
        if RELAX_JUNCTIONS:
            _relax_junctions(block_set, Xs, junctions, numbering, stencil)
        _slide(block_set, Xs, numbering, count, sliding)
        sweeps += 1
        output = _gather(Xs, numbering, count)
        previous, update = update, float(np.max(np.linalg.norm(output - before, axis=-1) / sizes))
        first = first or update
        if progress is not None:
            done = 1.0 if update < tol else np.log(first / update) / np.log(first / tol)
            progress(float(np.clip(done, 0.0, 1.0)), cycle=sweeps, update=update)
        if update < tol or not np.isfinite(update):
            state = output
            break
        if update > previous:
            mixing.restart()
        state = mixing.next_iterate(before, output)
        for X, ids in zip(Xs, numbering):
            X[...] = state[ids]
    info = {
        "solver": "Schwarz sweeps over the interfaces, each a glued two-block multigrid Winslow solve; Laplace at block junctions",
        "sweeps": sweeps,
        "iterations": sweeps,
        "final_update": float(update),
        "final_residual": None,  # not measured across blocks
        "tol": float(tol),
        "converged": bool(update < tol),
        "seconds": time.perf_counter() - start,
        "junction_nodes": int(len(junctions)),
    }
    if not info["converged"]:
        info["warnings"] = [
            f"multi-block elliptic solver did not converge: after {sweeps} sweep(s) the largest node update is "
            f"{update:.3g} of the local cell size (tolerance {tol:g}); raise --max-iter or --tol"
        ]
    return Xs, info
