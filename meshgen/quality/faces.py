"""Unstructured hexahedra and quadrilaterals (points + connectivity): face neighbours found by
matching the faces' node ids (``match_faces``), then the same compiled cell functions as the
structured path on the same corner coordinates, so both agree exactly."""

from __future__ import annotations

import numpy as np

from meshgen.errors import MeshgenError
from meshgen.quality.kernels import HEX_FACE_CORNERS, HEX_FACES, METRICS, QUAD_FACE_CORNERS, QUAD_FACES
from meshgen.quality.structured import apply_degenerate, degenerate_tolerance

__all__ = ["CELL_TYPES", "cell_metrics_unstructured", "cells_for_quality", "match_faces", "unstructured_metrics"]


def _sort4(columns):
    """Sort four integer columns row-wise with a five-comparator network (faster than np.sort(axis=1))."""
    a, b, c, d = columns
    a, b = np.minimum(a, b), np.maximum(a, b)
    c, d = np.minimum(c, d), np.maximum(c, d)
    a, c = np.minimum(a, c), np.maximum(a, c)
    b, d = np.minimum(b, d), np.maximum(b, d)
    b, c = np.minimum(b, c), np.maximum(b, c)
    return [a, b, c, d]


def _words(columns) -> list[np.ndarray]:
    """Row-sorted node-id columns as uint64 words, two ids per word where they fit in 32 bits
    (half the hashing and comparing): written side by side as uint32 and viewed as one uint64."""
    if max(int(c.max()) for c in columns) >= 2**32:
        return [c.astype(np.uint64) for c in columns]
    words = []
    for j in range(0, len(columns), 2):
        halves = np.empty((len(columns[j]), 2), dtype=np.uint32)
        halves[:, 0], halves[:, 1] = columns[j], columns[j + 1]
        words.append(halves.view(np.uint64).reshape(-1))
    return words


def _hash_rows(words) -> np.ndarray:
    """A well-mixed 64-bit hash of rows of uint64 words (wrapping uint64 arithmetic)."""
    h = np.full(len(words[0]), 0x9E3779B97F4A7C15, dtype=np.uint64)
    for word in words:
        h ^= word
        h *= np.uint64(0xBF58476D1CE4E5B9)
        h ^= h >> np.uint64(31)
    h *= np.uint64(0x94D049BB133111EB)
    h ^= h >> np.uint64(29)
    return h


def match_faces(face_nodes, hash_rows=_hash_rows) -> tuple[np.ndarray, int]:
    """Pair up equal faces.

    ``face_nodes``: k columns (k = 4 for hexahedra, 2 for quads), each (F,) node ids, one row per
    face. Returns ``partner`` (F,), the index of the other face with the same nodes, -1 for a face
    used once (boundary) or by more than two cells (non-manifold), and the number of non-manifold faces.

    Sorting a packed (hash | face index) uint64 is about 7x faster than argsort or lexsort; hash
    runs are verified against the node ids, and collisions fall back to an exact lexsort.
    """
    columns = list(face_nodes)
    F = len(columns[0])
    partner = np.full(F, -1, dtype=np.int64)
    if F == 0:
        return partner, 0
    if len(columns) == 4:
        columns = _sort4(columns)
    else:
        columns = [np.minimum(columns[0], columns[1]), np.maximum(columns[0], columns[1])]
    columns = _words(columns)
    index_bits = max(1, int(F - 1).bit_length())
    mask = np.uint64((1 << index_bits) - 1)
    packed = hash_rows(columns)
    packed &= ~mask
    packed |= np.arange(F, dtype=np.uint64)
    packed.sort()
    order = (packed & mask).view(np.int64)
    packed &= ~mask
    same_hash = packed[1:] == packed[:-1]
    del packed
    run_start = np.flatnonzero(np.concatenate([[True], ~same_hash]))
    run_length = np.diff(np.append(run_start, F))
    pairs = run_start[run_length == 2]
    first, second = order[pairs], order[pairs + 1]
    equal = np.ones(len(pairs), dtype=bool)
    for column in columns:
        equal &= column[first] == column[second]
    partner[first[equal]], partner[second[equal]] = second[equal], first[equal]
    # Hash collisions (unequal pairs, longer runs): match those faces exactly.
    unresolved = [order[pairs[~equal]], order[pairs[~equal] + 1]]
    for start, length in zip(run_start[run_length > 2], run_length[run_length > 2]):
        unresolved.append(order[start : start + length])
    unresolved = np.concatenate(unresolved)
    nonmanifold = 0
    if len(unresolved):
        keys = np.stack([column[unresolved] for column in columns])
        exact = np.lexsort(keys[::-1])
        faces, keys = unresolved[exact], keys[:, exact]
        same = np.all(keys[:, 1:] == keys[:, :-1], axis=0)
        starts = np.flatnonzero(np.concatenate([[True], ~same]))
        lengths = np.diff(np.append(starts, len(faces)))
        two = starts[lengths == 2]
        partner[faces[two]], partner[faces[two + 1]] = faces[two + 1], faces[two]
        nonmanifold = int(lengths[lengths > 2].sum())
    return partner, nonmanifold


def _used(cells, n_points) -> np.ndarray:
    """Boolean mask of the nodes that ``cells`` refer to (a scatter: faster than np.unique)."""
    used = np.zeros(n_points, dtype=bool)
    used[cells.reshape(-1)] = True
    return used


def _check_cells(points, cells):
    points = np.asarray(points, dtype=float)
    cells = np.asarray(cells)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise MeshgenError(f"points must have shape (N, 2) or (N, 3), got {points.shape}")
    if cells.ndim != 2 or cells.shape[1] not in (4, 8) or not np.issubdtype(cells.dtype, np.integer):
        raise MeshgenError(f"cells must be integer node ids of shape (M, 8) hexahedra or (M, 4) quads, got {cells.shape}")
    # int32 ids halve the memory traffic of the face matching
    cells = cells.astype(np.int32 if len(points) < 2**31 else np.int64, copy=False)
    if len(cells) and (cells.min() < 0 or cells.max() >= len(points)):
        raise MeshgenError(f"cells refer to nodes outside 0..{len(points) - 1}")
    dim = 3 if cells.shape[1] == 8 else 2
    if dim == 3 and points.shape[1] != 3:
        raise MeshgenError("hexahedra need 3D points")
    if dim == 2 and points.shape[1] == 3 and len(cells):
        z = points[_used(cells, len(points)), 2]
        z = z[np.isfinite(z)]
        xy = points[:, :2][np.isfinite(points[:, :2]).all(axis=1)]
        size = float(np.ptp(xy, axis=0).max()) if len(xy) else 0.0
        if len(z) and np.ptp(z) > 1e-9 * max(size, 1e-300):
            raise MeshgenError("the quadrilaterals do not lie in a plane z = const; surface quad meshes in 3D are not supported")
    return points[:, :dim], cells, dim


def unstructured_metrics(points, cells):
    """Per-cell metrics, degenerate mask, and info (boundary node ids, counts) of an unstructured mesh."""
    points, cells, dim = _check_cells(points, cells)
    if len(cells) == 0:
        raise MeshgenError("no cells to evaluate")
    from meshgen.quality import compiled, compiled_quad

    used = _used(cells, len(points))
    points = np.ascontiguousarray(points)
    tolerance, nonfinite = degenerate_tolerance(points[used])
    faces, face_corners = (HEX_FACES, HEX_FACE_CORNERS) if dim == 3 else (QUAD_FACES, QUAD_FACE_CORNERS)
    n_cells, n_faces = len(cells), len(faces)

    # Face f of cell c is row f * n_cells + c; one column per face corner (rows of the transposed
    # connectivity: contiguous copies, not a scattered gather).
    corner_rows = np.ascontiguousarray(cells.T)
    face_nodes = [corner_rows[face_corners[:, j]].reshape(-1) for j in range(face_corners.shape[1])]
    del corner_rows
    partner, nonmanifold = match_faces(face_nodes)
    neighbour_cell = np.where(partner >= 0, partner % n_cells, -1).reshape(n_faces, n_cells)
    open_faces = partner < 0
    boundary_nodes = np.flatnonzero(_used(np.concatenate([column[open_faces] for column in face_nodes]), len(points)))
    del face_nodes, partner

    cells = np.ascontiguousarray(cells)
    out = np.empty((len(METRICS), n_cells))
    degenerate = np.empty(n_cells, dtype=bool)
    if dim == 3:
        compiled.unstructured_hex(points, cells, neighbour_cell, float(tolerance), out, degenerate)
    else:
        d1 = points[cells[:, 2]] - points[cells[:, 0]]
        d2 = points[cells[:, 3]] - points[cells[:, 1]]
        orientation = 1.0 if float(np.nansum(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])) >= 0.0 else -1.0
        compiled_quad.unstructured_quad(points, cells, neighbour_cell, float(tolerance), orientation, out, degenerate)
    metrics = dict(zip(METRICS, out))
    apply_degenerate(metrics, degenerate)
    info = {"dim": dim, "nonfinite_nodes": nonfinite, "nonmanifold_faces": nonmanifold, "boundary_nodes": boundary_nodes}
    return metrics, degenerate, info


def cell_metrics_unstructured(points, cells) -> dict[str, np.ndarray]:
    """The seven per-cell metrics of an unstructured mesh.

    ``points``: (N, 3) or (N, 2) node coordinates (quads: z must be constant);
    ``cells``: (M, 8) hexahedra or (M, 4) quads, VTK corner order. Face neighbours (for
    non-orthogonality) are found from shared nodes. Returns arrays of length M keyed by ``METRICS``.
    """
    return unstructured_metrics(points, cells)[0]


CELL_TYPES = {"hexahedron": 3, "quad": 2}


def cells_for_quality(mesh) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """(points, cells, skipped) of a ``meshio.Mesh``: all hexahedra if there are any, else all
    quads; ``skipped`` counts the cells of every other type. MeshgenError if there are neither."""
    blocks: dict[str, list] = {}
    for block in mesh.cells:
        blocks.setdefault(block.type, []).append(np.asarray(block.data))
    kind = "hexahedron" if "hexahedron" in blocks else "quad" if "quad" in blocks else None
    counts = {name: int(sum(len(b) for b in data)) for name, data in blocks.items()}
    if kind is None:
        found = ", ".join(f"{n} {name}" for name, n in counts.items()) or "no cells"
        raise MeshgenError(f"no hexahedra or quadrilaterals to evaluate (found: {found})")
    cells = np.concatenate(blocks[kind]).astype(np.int64, copy=False)
    skipped = {name: n for name, n in counts.items() if name != kind and n}
    if len(cells) == 0:
        raise MeshgenError("the mesh has no cells")
    return np.asarray(mesh.points, dtype=float), cells, skipped
