"""Solver figures of a mesh made of blocks, measured on the merged mesh, where the blocks'
interfaces are interior faces: the expansion ratio and the grid smoothness
(``meshgen.quality.smoothness``'s definitions) and checkMesh's face non-orthogonality
(``meshgen.quality.faces_openfoam``'s), from hexahedra (2D: quads) in VTK corner order.

Each cell is measured in its own index directions (the corner order of its block): across a face
its neighbour is the cell on the other side, found by matching the faces' nodes
(``meshgen.quality.faces.match_faces``), so a grid line runs on from one block into the next.

- Expansion ratio of a cell: the largest over its faces with a neighbour of max(s, s') / min(s, s'),
  s and s' the two cells' mean edge lengths along the edges that leave the shared face.
- Grid smoothness of a node: the largest relative second difference |(q - n) - (n - p)| /
  ((|q - n| + |n - p|) / 2) over the node triples p, n, q of a grid line crossing a face at n (p
  in one cell, q in its neighbour); of a cell: the largest over its corners.
- Non-orthogonality: OpenFOAM's face centres and area vectors (the owner's corner order) and cell
  centres; an internal face's angle between S and the owner-to-neighbour centre vector, a boundary
  face's between its outward S and its cell's centre-to-face-centre vector. A 2D mesh is measured
  extruded one cell thick, its front and back faces left out.

Inside a block these are the structured figures of the block's node array (the same edges, node
triples and faces; equal to round-off); an interface adds the cells and node triples across it.
A block's figures (``block``) take its cells and every face one of its cells owns or neighbours,
so the whole mesh's figures are the largest of its blocks'.
"""

from __future__ import annotations

import numpy as np

from meshgen.quality.faces import match_faces
from meshgen.quality.faces_openfoam import ROOT_VSMALL, quad_centres_and_areas
from meshgen.quality.kernels import HEX_CORNER, HEX_FACES, QUAD_CORNER, QUAD_FACES
from meshgen.quality.report import assess, build_report

__all__ = ["merged_reports", "merged_solver_figures"]

SLAB = 1 << 18  # cells per slab of the face geometry (bounds the temporaries)


def _tables(dim: int):
    """(corner offsets (2^dim, dim), per face of ``HEX_FACES`` / ``QUAD_FACES``: its corners in the
    cyclic order whose right-hand normal points along +axis, and the corner across the cell from
    each)."""
    index = HEX_CORNER if dim == 3 else QUAD_CORNER
    faces = HEX_FACES if dim == 3 else QUAD_FACES
    cyclic, across = [], []
    for axis, side in faces:
        if dim == 3:
            first, second = (axis + 1) % 3, (axis + 2) % 3
            offsets = [(0, 0), (1, 0), (1, 1), (0, 1)]
        else:
            first, second, offsets = 1 - axis, None, [(0,), (1,)]
        corners, opposite = [], []
        for offset in offsets:
            bits = [0] * dim
            bits[axis] = side
            bits[first] = offset[0]
            if second is not None:
                bits[second] = offset[1]
            corners.append(index[tuple(bits)])
            bits[axis] = 1 - side
            opposite.append(index[tuple(bits)])
        cyclic.append(corners)
        across.append(opposite)
    return faces, np.array(cyclic), np.array(across)


def _norm(v: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("...i,...i->...", v, v))


def _cell_sizes(points, cells, dim) -> np.ndarray:
    """(M, dim): each cell's mean edge length along each of its index directions, averaged as
    ``meshgen.quality.smoothness`` does (pairs along the lower other axis first)."""
    index = HEX_CORNER if dim == 3 else QUAD_CORNER
    sizes = np.empty((len(cells), dim))
    for axis in range(dim):
        others = [d for d in range(dim) if d != axis]
        lengths = {}
        for bits in np.ndindex(*(2,) * (dim - 1)):
            low, high = [0] * dim, [0] * dim
            for d, b in zip(others, bits):
                low[d] = high[d] = b
            high[axis] = 1
            lengths[bits] = _norm(points[cells[:, index[tuple(high)]]] - points[cells[:, index[tuple(low)]]])
        for _ in others:  # halve along the lowest remaining other axis
            lengths = {key[1:]: 0.5 * (lengths[(0,) + key[1:]] + lengths[(1,) + key[1:]]) for key in lengths if key[0] == 0}
        sizes[:, axis] = lengths[()]
    return sizes


def _face_geometry(points3, cells, cyclic) -> tuple[np.ndarray, np.ndarray]:
    """OpenFOAM's centres and area vectors (F, M, 3) of every face of every cell (corners in
    ``cyclic`` order: area vectors along +axis on a right-handed cell), by ``meshgen.quality.faces_openfoam.quad_centres_and_areas``."""
    xyz = [np.ascontiguousarray(points3[:, c]) for c in range(3)]
    columns = np.ascontiguousarray(cells.T)
    centres = np.empty((len(cyclic), len(cells), 3))
    areas = np.empty_like(centres)
    for f, corners in enumerate(cyclic):
        centres[f], areas[f] = quad_centres_and_areas([[x[columns[k]] for x in xyz] for k in corners])
    return centres, areas


def _cell_centres(centres, outward) -> np.ndarray:
    """OpenFOAM's cell centres (M, 3) from the faces' centres and outward area vectors (F, M, 3)."""
    estimate = sum(centres[2 * a] + centres[2 * a + 1] for a in range(3)) / 6.0
    volume = np.zeros(centres.shape[1])
    weighted = np.zeros_like(estimate)
    for f in range(len(centres)):
        pyramid = np.einsum("ij,ij->i", outward[f], centres[f] - estimate)
        volume += pyramid
        weighted += pyramid[:, None] * (0.75 * centres[f] + 0.25 * estimate)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((np.abs(volume) > 1e-300)[:, None], weighted / volume[:, None], estimate)


def _cosines(d, S) -> np.ndarray:
    return np.einsum("ij,ij->i", d, S) / (_norm(d) * _norm(S) + ROOT_VSMALL)


def _extruded(points, cells):
    """A quad mesh as one layer of hexahedra (VTK order: the quad at z = 0, then at z = 1)."""
    points3 = np.zeros((2 * len(points), 3))
    points3[: len(points), :2] = points3[len(points) :, :2] = points
    points3[len(points) :, 2] = 1.0
    return points3, np.concatenate([cells, cells + len(points)], axis=1)


def _place(cell: int, block, offsets, cell_shapes, names) -> tuple[object, list[int]]:
    """(block name or None, the cell's index in its block (or in the merged mesh))."""
    if block is None:
        return None, [int(cell)]
    b = int(block[cell])
    return names[b], [int(i) for i in np.unravel_index(int(cell) - int(offsets[b]), cell_shapes[b])]


def _cell_summary(values, chosen, locate) -> dict:
    values = values[chosen]
    cells = np.flatnonzero(chosen)
    finite = values[np.isfinite(values)]
    worst = int(np.argmax(np.where(np.isnan(values), -np.inf, values)))
    block, index = locate(cells[worst])
    return {
        "mean": float(finite.mean()) if finite.size else None,
        "max": float(values[worst]),
        "p99": float(np.percentile(finite, 99.0)) if finite.size else None,
        "worst_cell": index,
        **({"worst_block": block} if block is not None else {}),
    }


def _face_summary(cosines, cell, face, axes, locate) -> dict:
    if not len(cosines):
        return {"max": None, "average": None, "worst_face": None, "faces": 0}
    worst = int(np.argmin(cosines))
    block, index = locate(cell[worst])
    axis, side = axes[face[worst]]
    if len(index) > 1:
        index[axis] += side  # the face's node layer along its axis, as the structured figure says
    return {
        "max": float(np.degrees(np.arccos(np.clip(cosines[worst], -1.0, 1.0)))),
        "average": float(np.degrees(np.arccos(np.clip(float(cosines.sum()) / len(cosines), -1.0, 1.0)))),
        "worst_face": {"axis": int(axis), "index": index, **({"block": block} if block is not None else {})},
        "faces": int(len(cosines)),
    }


def merged_solver_figures(points, cells, block=None, names=(), cell_shapes=()) -> list[dict]:
    """The solver figures (``expansion_ratio``, ``grid_smoothness``, ``non_orthogonality_internal``,
    ``non_orthogonality_boundary``: the keys and statistics of a structured report's
    ``solver_figures``) of the merged mesh ``points`` (N, dim), ``cells`` (M, 2^dim) VTK order,
    interfaces matched as interior faces (module docstring). With ``block`` (M,) the block of each
    cell (cells block after block, each block's in C order of its ``cell_shapes``) and the blocks'
    ``names``: [the whole mesh's figures, then each block's]; worst cells and faces are located by
    block name (``worst_block``, ``worst_face["block"]``) and index in the block. Without: [the
    whole mesh's], cells located by their number."""
    points = np.asarray(points, dtype=float)
    cells = np.asarray(cells, dtype=np.int64)
    dim = 3 if cells.shape[1] == 8 else 2
    points = points[:, :dim]
    n_cells = len(cells)
    axes, cyclic, across = _tables(dim)
    n_faces = len(axes)
    corner_rows = [cells[:, cyclic[f]] for f in range(n_faces)]  # (M, corners) per face
    columns = [np.concatenate([rows[:, j] for rows in corner_rows]) for j in range(cyclic.shape[1])]
    partner, _ = match_faces([c.astype(np.int64) for c in columns])
    slot_face, slot_cell = np.divmod(np.arange(n_faces * n_cells), n_cells)
    inner = np.flatnonzero(partner >= 0)
    c_p, c_n = slot_cell[inner], slot_cell[partner[inner]]

    # Expansion ratio: the sizes along the edges that leave the shared face, both sides; face by
    # face, each cell at most once per face (no scatter needed).
    sizes = _cell_sizes(points, cells, dim)
    axis_of = np.array([a for a, _ in axes])
    expansion = np.ones(n_cells)
    for f, (axis, _) in enumerate(axes):
        mine = np.flatnonzero(partner[f * n_cells : (f + 1) * n_cells] >= 0)
        other = partner[f * n_cells + mine]
        a, b = sizes[mine, axis], sizes[other % n_cells, axis_of[other // n_cells]]
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.maximum(a, b) / np.minimum(a, b)
        expansion[mine] = np.fmax(expansion[mine], np.where(np.isnan(ratio), np.inf, ratio))

    # Grid smoothness: at each corner n of each internal face (once, from its owner's side), p
    # across the owner, q across the neighbour; a node's value the largest of its triples.
    owned = inner[c_p < c_n]
    f_p, o_p = slot_face[owned], slot_cell[owned]
    f_n, o_n = slot_face[partner[owned]], slot_cell[partner[owned]]
    nodes_p = cells[o_p[:, None], cyclic[f_p]]  # (K, corners)
    nodes_n = cells[o_n[:, None], cyclic[f_n]]
    position = np.argmax(nodes_p[:, :, None] == nodes_n[:, None, :], axis=2)  # where each of P's corners is in N's face
    p_nodes = cells[o_p[:, None], across[f_p]]
    q_nodes = cells[o_n[:, None], across[f_n][np.arange(len(owned))[:, None], position]]
    n_xyz = points[nodes_p]
    forward, backward = points[q_nodes] - n_xyz, n_xyz - points[p_nodes]
    second = _norm(forward - backward)
    spacing = 0.5 * (_norm(forward) + _norm(backward))
    with np.errstate(divide="ignore", invalid="ignore"):
        value = np.where(spacing > 0, second / spacing, np.where(second > 0, np.inf, 0.0)).reshape(-1)
    flat = nodes_p.reshape(-1)
    order = np.argsort(flat, kind="stable")
    flat = flat[order]
    starts = np.flatnonzero(np.concatenate([[True], flat[1:] != flat[:-1]])) if len(flat) else np.zeros(0, dtype=np.int64)
    node_value = np.zeros(len(points))
    if len(flat):
        node_value[flat[starts]] = np.fmax(0.0, np.fmax.reduceat(value[order], starts))
    smoothness = np.fmax.reduce(node_value[cells], axis=1)

    # Non-orthogonality (checkMesh's), on the hexahedra (a quad mesh extruded).
    points3, cells3 = (points, cells) if dim == 3 else _extruded(points, cells)
    _, cyclic3, _ = _tables(3)
    centres, areas = _face_geometry(points3, cells3, cyclic3)
    side_sign = np.array([-1.0 if side == 0 else 1.0 for _, side in HEX_FACES])[:, None, None]
    outward = side_sign * areas
    orientation = 1.0 if float(np.einsum("fmi,fmi->", centres, outward)) >= 0 else -1.0
    outward *= orientation
    C = _cell_centres(centres, outward)
    o_face, o_cell, o_other = f_p, o_p, o_n  # each internal face once, from its owner (the lower-numbered cell)
    internal = _cosines(C[o_other] - C[o_cell], outward[o_face, o_cell])
    open_slots = np.flatnonzero(partner < 0)
    b_face, b_cell = slot_face[open_slots], slot_cell[open_slots]
    boundary = _cosines(centres[b_face, b_cell] - C[b_cell], outward[b_face, b_cell])

    offsets = np.concatenate([[0], np.cumsum([int(np.prod(s)) for s in cell_shapes])]) if block is not None else None

    def locate(cell):
        return _place(cell, block, offsets, cell_shapes, names)

    def figures(chosen):
        return {
            "expansion_ratio": _cell_summary(expansion, chosen, locate),
            "grid_smoothness": _cell_summary(smoothness, chosen, locate),
            "non_orthogonality_internal": _face_summary(
                internal[chosen[o_cell] | chosen[o_other]],
                o_cell[chosen[o_cell] | chosen[o_other]],
                o_face[chosen[o_cell] | chosen[o_other]],
                axes,
                locate,
            ),
            "non_orthogonality_boundary": _face_summary(
                boundary[chosen[b_cell]], b_cell[chosen[b_cell]], b_face[chosen[b_cell]], axes, locate
            ),
        }

    every = np.ones(n_cells, dtype=bool)
    if block is None:
        return [figures(every)]
    block = np.asarray(block)
    return [figures(every)] + [figures(block == b) for b in range(len(names))]


def merged_reports(points, cells, block=None, names=(), cell_shapes=(), geometry=None, deviation=None) -> list[dict]:
    """Quality reports (``meshgen.quality.report.quality_report``'s schema, ``structured`` False)
    of a merged mesh: [the whole mesh's, then each block's (``block`` its name)] where ``block``
    (M,) gives each cell's block (see :func:`merged_solver_figures`), else [the whole mesh's].
    The per-cell metrics are measured once on the merged mesh (an interface face's
    non-orthogonality with the neighbour cell, whichever block it is in), a block's summaries
    taken over its cells; ``solver_figures`` are :func:`merged_solver_figures`. ``geometry`` (a
    Geometry or ``meshgen.geometry.blocks.BlockSet``) with ``deviation`` (its boundary deviation,
    or a callable of the boundary nodes' coordinates (K, dim) returning it) adds the whole mesh's
    ``boundary_deviation``."""
    metrics, degenerate, info = assess((points, cells))
    figures = merged_solver_figures(points, cells, block, names, cell_shapes)
    whole = dict(info, solver_figures=lambda: figures[0])
    if geometry is not None and deviation is not None:
        whole["boundary_deviation"] = (lambda: deviation(info["boundary"]()[0])) if callable(deviation) else deviation
    reports = [{"structured": False, **build_report(metrics, degenerate, whole, geometry)}]
    for index, name in enumerate(names if block is not None else ()):
        chosen = np.asarray(block) == index
        part = {"dim": info["dim"], "solver_figures": lambda figure=figures[index + 1]: figure}
        summaries = {key: values[chosen] for key, values in metrics.items()}
        reports.append({"block": name, "structured": False, **build_report(summaries, degenerate[chosen], part, None)})
    return reports
