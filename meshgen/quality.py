"""Mesh quality: the per-cell metrics of DESIGN section 7, their summaries and the validity verdict.

Per cell, for hexahedra (quadrilaterals: the one face, edges instead of faces):

- ``min_angle``, ``max_angle`` (degrees): over the 24 face corners (6 faces x 4 corners), the angle
  between the two edges at the corner. As in Verdict (VTK's ``vtkMeshQuality``), a face with a reflex
  corner (a corner normal that opposes the face's normal at its centre) reports ``360 - angle`` as
  its largest angle, so a folded face shows a maximum angle above 180.
- ``equiangle_skewness``: max((max_angle - 90) / 90, (90 - min_angle) / 90); 0 best, 1 worst
  for convex faces (above 1 only with a reflex corner).
- ``aspect_ratio``: mean edge length along each index direction; largest over smallest (>= 1).
- ``centroid_skewness``: 1 - min over the faces of |n_f . e|, n_f the unit face normal, e the
  unit vector from the cell centroid to the face centroid; 0 best.
- ``non_orthogonality`` (degrees): per face the angle between the face normal and the line joining
  the centroids of the two cells that share it (boundary faces: cell centroid to face centroid);
  per cell the largest over its faces.
- ``scaled_jacobian``: min over the corners of det(e1, e2, e3) / (|e1| |e2| |e3|), the corner's
  three edges in right-handed order (Verdict's corner Jacobians); <= 0 means inverted.
  Quadrilaterals: e1 x e2 / (|e1| |e2|) against the mesh's orientation (the sign of its total area).

The normal of a (generally non-planar) hex face is the normal of the bilinear face at its centre:
the cross product of its diagonals, normalised. The centroid of a cell or face is the mean of its
corner nodes.

A cell is *degenerate* when an edge has zero length (at most 1e-12 of the mesh's bounding-box
diagonal) or a corner is not finite. Degenerate cells count as inverted; their per-cell values are
set to the worst ones (angles 0 and 180, skewnesses 1, non-orthogonality 90, aspect ratio inf,
scaled Jacobian <= 0) and the summaries (mean, min, max, 1st and 99th percentiles) are taken over
the other cells, so they are never NaN. A mesh is valid when at most 0.5% of its cells are inverted.

Everything is vectorised over cells; cells are processed in blocks of about 16 000 so that the
temporaries stay in cache (about 3x faster than whole-array passes at 1e6 cells). The structured
path (node arrays) and the unstructured one (points + connectivity, face neighbours found from
shared nodes) run the same kernel on the same corner coordinates, so they agree exactly.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from meshgen.errors import MeshgenError

METRICS = (
    "min_angle",
    "max_angle",
    "equiangle_skewness",
    "aspect_ratio",
    "centroid_skewness",
    "non_orthogonality",
    "scaled_jacobian",
)
STATS = ("mean", "min", "max", "p01", "p99")
VALID_FRACTION = 0.005
VALID_RULE = "inverted cells <= 0.5% of all cells (inverted: scaled Jacobian <= 0 at a corner, or degenerate)"
DEGENERATE_TOLERANCE = 1e-12  # edge length, relative to the bounding-box diagonal

DEFINITIONS = {
    "min_angle": "smallest face-corner angle between the two edges at the corner (degrees)",
    "max_angle": "largest face-corner angle; a reflex corner of a face counts as 360 - angle, as in Verdict (degrees)",
    "equiangle_skewness": "max((max_angle - 90)/90, (90 - min_angle)/90); 0 best",
    "aspect_ratio": "mean edge length per index direction, largest over smallest; 1 best",
    "centroid_skewness": "1 - min over faces |n_f . e|, e the unit vector from cell centroid to face centroid; 0 best",
    "non_orthogonality": "max over faces of the angle between face normal and the line joining the two cell "
    "centroids (boundary faces: cell centroid to face centroid) (degrees)",
    "scaled_jacobian": "min over corners of det(e1, e2, e3)/(|e1||e2||e3|), right-handed corner edges; <= 0 inverted",
}
# Values given to degenerate cells in the per-cell arrays (the summaries leave those cells out).
WORST = {
    "min_angle": 0.0,
    "max_angle": 180.0,
    "equiangle_skewness": 1.0,
    "aspect_ratio": np.inf,
    "centroid_skewness": 1.0,
    "non_orthogonality": 90.0,
}

BLOCK_CELLS = 16384  # cells per block: the kernel's temporaries then stay in a 2-4 MiB cache (measured best)

# Corner offsets (s0, s1[, s2]) -> VTK corner index (hexahedron, quad), as meshgen.grid writes them.
HEX_CORNER = {(0, 0, 0): 0, (1, 0, 0): 1, (1, 1, 0): 2, (0, 1, 0): 3, (0, 0, 1): 4, (1, 0, 1): 5, (1, 1, 1): 6, (0, 1, 1): 7}
QUAD_CORNER = {(0, 0): 0, (1, 0): 1, (1, 1): 2, (0, 1): 3}
# Faces in kernel order: (normal axis, side); the VTK corners of each (unordered: to match faces).
HEX_FACES = [(axis, side) for axis in range(3) for side in (0, 1)]
QUAD_FACES = [(axis, side) for axis in range(2) for side in (0, 1)]


def _face_corner_table(corner_index: dict, faces) -> np.ndarray:
    return np.array([[k for s, k in corner_index.items() if s[axis] == side] for axis, side in faces])


HEX_FACE_CORNERS = _face_corner_table(HEX_CORNER, HEX_FACES)  # (6, 4)
QUAD_FACE_CORNERS = _face_corner_table(QUAD_CORNER, QUAD_FACES)  # (4, 2)


# ---------------------------------------------------------------------------------------------
# vector algebra on tuples of component arrays (x, y[, z]): no stacking, no copies


def _sub(a, b):
    return tuple(p - q for p, q in zip(a, b))


def _add(a, b):
    return tuple(p + q for p, q in zip(a, b))


def _dot(a, b):
    result = a[0] * b[0]
    for p, q in zip(a[1:], b[1:]):
        result += p * q
    return result


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _cross2(a, b):
    """z component of the cross product of two plane vectors."""
    return a[0] * b[1] - a[1] * b[0]


def _unit(a):
    """(a / |a|, |a|); a zero vector stays zero, so no NaN comes from a degenerate edge or face."""
    length = np.sqrt(_dot(a, a))
    inverse = 1.0 / np.where(length > 0.0, length, 1.0)
    return tuple(p * inverse for p in a), length


def _degrees_of_cosine(cosine):
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def _neighbour_direction(neighbour_centroid, centroid, boundary_direction):
    """Unit vector from a cell centroid to its neighbour's across a face; where there is no
    neighbour (NaN centroid: boundary, or a neighbour with non-finite nodes) the given direction."""
    d = _sub(neighbour_centroid, centroid)
    inside = np.isfinite(sum(d))  # one test for all components: a NaN or inf anywhere shows in the sum
    d = tuple(np.where(inside, p, q) for p, q in zip(d, boundary_direction))
    return _unit(d)[0]


# ---------------------------------------------------------------------------------------------
# the kernels: one block of cells, corners given as component tuples of equal-shaped arrays


def _hex_kernel(corner, centroid, neighbour_centroid, tolerance):
    """Metrics of a block of hexahedra.

    ``corner``: dict (s0, s1, s2) -> (x, y, z) arrays of one shape (the block's cells).
    ``centroid``: (x, y, z) of the cells; ``neighbour_centroid``: dict (axis, side) -> (x, y, z) of
    the cell across that face, NaN where there is none. Returns (metrics dict, degenerate mask).
    """
    # Edges along each index direction, keyed by the offsets along the other two axes (ascending).
    unit_edge, axis_sum, mean_length = [{}, {}, {}], [None] * 3, [None] * 3
    shortest_edge = None
    for axis in range(3):
        others = [d for d in range(3) if d != axis]
        lengths = []
        for t in ((0, 0), (1, 0), (0, 1), (1, 1)):
            low = [0, 0, 0]
            low[others[0]], low[others[1]] = t
            high = list(low)
            high[axis] = 1
            edge = _sub(corner[tuple(high)], corner[tuple(low)])
            unit_edge[axis][t], length = _unit(edge)
            lengths.append(length)
            axis_sum[axis] = edge if axis_sum[axis] is None else _add(axis_sum[axis], edge)
            shortest_edge = length if shortest_edge is None else np.minimum(shortest_edge, length)
        mean_length[axis] = (lengths[0] + lengths[1] + lengths[2] + lengths[3]) * 0.25
    degenerate = ~(shortest_edge > tolerance)  # np.minimum keeps NaN: non-finite cells count too

    longest = np.maximum(np.maximum(mean_length[0], mean_length[1]), mean_length[2])
    shortest = np.minimum(np.minimum(mean_length[0], mean_length[1]), mean_length[2])
    with np.errstate(divide="ignore", invalid="ignore"):
        aspect_ratio = np.where(shortest > 0.0, longest / np.where(shortest > 0.0, shortest, 1.0), np.inf)

    # Scaled Jacobian: at corner (s0, s1, s2) the three edges of the cell that meet there, each taken
    # in the +index direction; flipping an edge and reordering them to right-handed order cancel, so
    # the corner value is det(u0, u1, u2) of the forward unit edges.
    # The cross products u1 x u2 are also the corner normals of the faces normal to axis 0.
    scaled_jacobian, axis0_corner_normal = None, {}
    for s0, s1, s2 in HEX_CORNER:
        corner_normal = _cross(unit_edge[1][(s0, s2)], unit_edge[2][(s0, s1)])
        axis0_corner_normal[(s0, s1, s2)] = corner_normal
        value = _dot(unit_edge[0][(s1, s2)], corner_normal)
        scaled_jacobian = value if scaled_jacobian is None else np.minimum(scaled_jacobian, value)

    principal = [_unit(axis_sum[axis])[0] for axis in range(3)]  # centroid -> face centroid, up to sign
    largest_cosine = smallest_cosine = reflex_cosine = any_reflex = None
    centroid_alignment = face_alignment = None
    for axis, side in HEX_FACES:
        a, b = [d for d in range(3) if d != axis]

        def key(edge_axis, offset):
            offsets = {axis: side, (b if edge_axis == a else a): offset}
            return tuple(offsets[d] for d in range(3) if d != edge_axis)

        ua = {tb: unit_edge[a][key(a, tb)] for tb in (0, 1)}  # edges along a at b-offset tb
        ub = {ta: unit_edge[b][key(b, ta)] for ta in (0, 1)}  # edges along b at a-offset ta

        def node(ta, tb):
            offsets = {axis: side, a: ta, b: tb}
            return corner[(offsets[0], offsets[1], offsets[2])]

        normal = _cross(_sub(node(1, 1), node(0, 0)), _sub(node(0, 1), node(1, 0)))
        # Corner (ta, tb) of the face: its edges are ua[tb] and ub[ta], both pointing away from the
        # corner when ta == tb, one reversed otherwise.
        cosines = (_dot(ua[0], ub[0]), -_dot(ua[0], ub[1]), _dot(ua[1], ub[1]), -_dot(ua[1], ub[0]))
        face_max = np.maximum(np.maximum(cosines[0], cosines[1]), np.maximum(cosines[2], cosines[3]))
        face_min = np.minimum(np.minimum(cosines[0], cosines[1]), np.minimum(cosines[2], cosines[3]))
        # Signed corner areas n . (ua[tb] x ub[ta]); a negative one marks a reflex corner. Faces normal
        # to axis 0 reuse the Jacobian's cross products; the others use n . (ua x ub) = ub . (n x ua).
        if axis == 0:
            areas = [_dot(normal, axis0_corner_normal[(side, ta, tb)]) for ta, tb in ((0, 0), (1, 0), (1, 1), (0, 1))]
        else:
            m0, m1 = _cross(normal, ua[0]), _cross(normal, ua[1])
            areas = [_dot(m0, ub[0]), _dot(m0, ub[1]), _dot(m1, ub[1]), _dot(m1, ub[0])]
        reflex = np.minimum(np.minimum(areas[0], areas[1]), np.minimum(areas[2], areas[3])) < 0.0

        unit_normal = _unit(normal)[0]
        centroid_cosine = np.abs(_dot(unit_normal, principal[axis]))
        towards_neighbour = _neighbour_direction(neighbour_centroid[(axis, side)], centroid, principal[axis])
        face_cosine = np.abs(_dot(unit_normal, towards_neighbour))

        if largest_cosine is None:
            largest_cosine, smallest_cosine = face_max, face_min
            reflex_cosine, any_reflex = np.where(reflex, face_min, -2.0), reflex
            centroid_alignment, face_alignment = centroid_cosine, face_cosine
        else:
            largest_cosine = np.maximum(largest_cosine, face_max)
            smallest_cosine = np.minimum(smallest_cosine, face_min)
            reflex_cosine = np.maximum(reflex_cosine, np.where(reflex, face_min, -2.0))
            any_reflex |= reflex
            centroid_alignment = np.minimum(centroid_alignment, centroid_cosine)
            face_alignment = np.minimum(face_alignment, face_cosine)

    return _finish(
        largest_cosine, smallest_cosine, reflex_cosine, any_reflex, aspect_ratio, centroid_alignment, face_alignment, scaled_jacobian
    ), degenerate


def _quad_kernel(corner, centroid, neighbour_centroid, tolerance, orientation):
    """Metrics of a block of quadrilaterals in the plane (see ``_hex_kernel``); ``orientation`` is
    +1 or -1, the sign of the mesh's total area: corners turning the other way are inverted."""
    unit_edge, axis_sum, mean_length = [{}, {}], [None, None], [None, None]
    shortest_edge = None
    for axis in range(2):
        lengths = []
        for t in (0, 1):
            low = [t, t]
            low[axis] = 0
            high = list(low)
            high[axis] = 1
            edge = _sub(corner[tuple(high)], corner[tuple(low)])
            unit_edge[axis][t], length = _unit(edge)
            lengths.append(length)
            axis_sum[axis] = edge if axis_sum[axis] is None else _add(axis_sum[axis], edge)
            shortest_edge = length if shortest_edge is None else np.minimum(shortest_edge, length)
        mean_length[axis] = (lengths[0] + lengths[1]) * 0.5
    degenerate = ~(shortest_edge > tolerance)
    longest = np.maximum(mean_length[0], mean_length[1])
    shortest = np.minimum(mean_length[0], mean_length[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        aspect_ratio = np.where(shortest > 0.0, longest / np.where(shortest > 0.0, shortest, 1.0), np.inf)

    u0, u1 = unit_edge
    # Corner (ta, tb): edges u0[tb] and u1[ta]; cosines as for a hex face, corner areas u0[tb] x u1[ta].
    cosines = (_dot(u0[0], u1[0]), -_dot(u0[0], u1[1]), _dot(u0[1], u1[1]), -_dot(u0[1], u1[0]))
    areas = (_cross2(u0[0], u1[0]), _cross2(u0[0], u1[1]), _cross2(u0[1], u1[1]), _cross2(u0[1], u1[0]))
    largest_cosine = np.maximum(np.maximum(cosines[0], cosines[1]), np.maximum(cosines[2], cosines[3]))
    smallest_cosine = np.minimum(np.minimum(cosines[0], cosines[1]), np.minimum(cosines[2], cosines[3]))
    smallest_area = np.minimum(np.minimum(areas[0], areas[1]), np.minimum(areas[2], areas[3]))
    largest_area = np.maximum(np.maximum(areas[0], areas[1]), np.maximum(areas[2], areas[3]))
    # Reflex corner: a corner area of the other sign than the quad's area at its centre (diagonals).
    centre_area = _cross2(_sub(corner[(1, 1)], corner[(0, 0)]), _sub(corner[(0, 1)], corner[(1, 0)]))
    reflex = np.where(centre_area >= 0.0, smallest_area < 0.0, largest_area > 0.0)
    scaled_jacobian = smallest_area if orientation > 0 else -largest_area

    principal = [_unit(axis_sum[axis])[0] for axis in range(2)]
    centroid_alignment = face_alignment = None
    for axis, side in QUAD_FACES:
        along = u1[side] if axis == 0 else u0[side]  # the face is the edge across the normal axis
        # |n . e| with n the edge's in-plane normal is |along x e|.
        centroid_cosine = np.abs(_cross2(along, principal[axis]))
        towards_neighbour = _neighbour_direction(neighbour_centroid[(axis, side)], centroid, principal[axis])
        face_cosine = np.abs(_cross2(along, towards_neighbour))
        if centroid_alignment is None:
            centroid_alignment, face_alignment = centroid_cosine, face_cosine
        else:
            centroid_alignment = np.minimum(centroid_alignment, centroid_cosine)
            face_alignment = np.minimum(face_alignment, face_cosine)

    reflex_cosine = np.where(reflex, smallest_cosine, -2.0)
    return _finish(
        largest_cosine, smallest_cosine, reflex_cosine, reflex, aspect_ratio, centroid_alignment, face_alignment, scaled_jacobian
    ), degenerate


def _finish(largest_cosine, smallest_cosine, reflex_cosine, any_reflex, aspect_ratio, centroid_alignment, face_alignment, scaled_jacobian):
    """Angles from cosines (one arccos per cell and kind), then the derived metrics."""
    min_angle = _degrees_of_cosine(largest_cosine)
    max_angle = _degrees_of_cosine(smallest_cosine)
    # A face with a reflex corner reports 360 - its largest unsigned angle (above 180, so it wins);
    # of several such faces the one with the smallest unsigned largest angle gives the largest value.
    if any_reflex.any():
        max_angle[any_reflex] = 360.0 - _degrees_of_cosine(reflex_cosine[any_reflex])
    equiangle_skewness = np.maximum((max_angle - 90.0) / 90.0, (90.0 - min_angle) / 90.0)
    return {
        "min_angle": min_angle,
        "max_angle": max_angle,
        "equiangle_skewness": equiangle_skewness,
        "aspect_ratio": aspect_ratio,
        "centroid_skewness": 1.0 - centroid_alignment,
        "non_orthogonality": _degrees_of_cosine(face_alignment),
        "scaled_jacobian": scaled_jacobian,
    }


# ---------------------------------------------------------------------------------------------
# structured node arrays


def _check_node_array(X) -> np.ndarray:
    X = np.asarray(X, dtype=float)
    if X.ndim not in (3, 4) or X.shape[-1] != X.ndim - 1 or min(X.shape[:-1]) < 2:
        raise MeshgenError(
            f"node array must have shape (n1+1, n2+1[, n3+1], dim) with >= 2 nodes per axis, got {X.shape}"
        )
    return X


def _tolerance(points_or_components) -> tuple[float, int]:
    """Degenerate-edge length and the number of non-finite nodes, from the finite coordinates."""
    components = points_or_components
    finite = np.ones(components[0].shape, dtype=bool)
    for c in components:
        finite &= np.isfinite(c)
    nonfinite = int(finite.size - np.count_nonzero(finite))
    if not finite.any():
        return 0.0, nonfinite
    extent = np.sqrt(sum(float(np.ptp(c[finite])) ** 2 for c in components))
    return DEGENERATE_TOLERANCE * extent, nonfinite


def _orientation_2d(corner) -> float:
    """+1 if the quads' total signed area (diagonal cross products) is >= 0, else -1."""
    area = _cross2(_sub(corner[(1, 1)], corner[(0, 0)]), _sub(corner[(0, 1)], corner[(1, 0)]))
    total = float(np.nansum(area))
    return 1.0 if total >= 0.0 else -1.0


def _apply_degenerate(metrics: dict, degenerate: np.ndarray) -> None:
    if not degenerate.any():
        return
    for name, worst in WORST.items():
        metrics[name][degenerate] = worst
    sj = metrics["scaled_jacobian"]
    sj[degenerate] = np.minimum(np.where(np.isfinite(sj[degenerate]), sj[degenerate], 0.0), 0.0)


def _structured(X):
    """Per-cell metrics (C order of cells) and the degenerate mask of node array ``X``."""
    X = _check_node_array(X)
    dim = X.shape[-1]
    node_shape = X.shape[:-1]
    cell_shape = tuple(n - 1 for n in node_shape)
    n_cells = int(np.prod(cell_shape))
    components = tuple(np.ascontiguousarray(X[..., c]) for c in range(dim))
    tolerance, nonfinite = _tolerance(components)
    offsets = HEX_CORNER if dim == 3 else QUAD_CORNER

    def corners(first, last):
        """Views of the corners of the cells first..last-1 along axis 0."""
        return {
            s: tuple(
                c[(slice(first + s[0], last + s[0]),) + tuple(slice(o, o + n) for o, n in zip(s[1:], cell_shape[1:]))]
                for c in components
            )
            for s in offsets
        }

    all_corners = corners(0, cell_shape[0])
    weight = 1.0 / len(offsets)
    centroid = tuple(sum(corner[c] for corner in all_corners.values()) * weight for c in range(dim))
    # NaN margin of one cell on every side: the neighbour across a boundary face is "none".
    padded = tuple(np.pad(c, 1, constant_values=np.nan) for c in centroid)
    orientation = _orientation_2d(all_corners) if dim == 2 else 1.0
    faces = HEX_FACES if dim == 3 else QUAD_FACES

    metrics = {name: np.empty(cell_shape) for name in METRICS}
    degenerate = np.empty(cell_shape, dtype=bool)
    rows = max(1, BLOCK_CELLS // max(1, int(np.prod(cell_shape[1:]))))
    for first in range(0, cell_shape[0], rows):
        last = min(cell_shape[0], first + rows)
        inner = (slice(first + 1, last + 1),) + tuple(slice(1, n + 1) for n in cell_shape[1:])
        block_centroid = tuple(p[inner] for p in padded)
        neighbour = {}
        for axis, side in faces:
            shift = [0] * dim
            shift[axis] = 1 if side else -1
            index = tuple(slice(s.start + d, s.stop + d) for s, d in zip(inner, shift))
            neighbour[(axis, side)] = tuple(p[index] for p in padded)
        block = corners(first, last)
        if dim == 3:
            values, short = _hex_kernel(block, block_centroid, neighbour, tolerance)
        else:
            values, short = _quad_kernel(block, block_centroid, neighbour, tolerance, orientation)
        for name in METRICS:
            metrics[name][first:last] = values[name]
        degenerate[first:last] = short
    metrics = {name: values.reshape(n_cells) for name, values in metrics.items()}
    degenerate = degenerate.reshape(n_cells)
    _apply_degenerate(metrics, degenerate)
    return metrics, degenerate, {"nonfinite_nodes": nonfinite}


def cell_metrics(X) -> dict[str, np.ndarray]:
    """The seven per-cell metrics of node array ``X`` (shape ``(n1+1, n2+1[, n3+1], dim)``).

    Returns a dict keyed by ``METRICS``, each an array of length n1*n2[*n3] in C order of the
    cells (i, j[, k]), float64. Angles and non-orthogonality in degrees.
    """
    return _structured(X)[0]


# ---------------------------------------------------------------------------------------------
# unstructured hexahedra and quadrilaterals


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
            raise MeshgenError(
                "the quadrilaterals do not lie in a plane z = const; surface quad meshes in 3D are not supported"
            )
    return points[:, :dim], cells, dim


def _unstructured(points, cells):
    """Per-cell metrics, degenerate mask, and info (boundary node ids, counts) of an unstructured mesh."""
    points, cells, dim = _check_cells(points, cells)
    if len(cells) == 0:
        raise MeshgenError("no cells to evaluate")
    used = _used(cells, len(points))
    components = tuple(np.ascontiguousarray(points[:, c]) for c in range(dim))
    tolerance, nonfinite = _tolerance(tuple(c[used] for c in components))
    offsets = HEX_CORNER if dim == 3 else QUAD_CORNER
    faces, face_corners = (HEX_FACES, HEX_FACE_CORNERS) if dim == 3 else (QUAD_FACES, QUAD_FACE_CORNERS)
    n_cells, n_faces = len(cells), len(faces)

    weight = 1.0 / len(offsets)
    # Summed in the corner order of the structured path, so both give bitwise equal centroids.
    centroid = tuple(sum(c[cells[:, k]] for k in offsets.values()) * weight for c in components)
    # One trailing NaN: neighbour index -1 (no neighbour) then reads "none".
    centroid_ext = tuple(np.append(c, np.nan) for c in centroid)

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

    if dim == 2:
        all_corners = {s: tuple(c[cells[:, k]] for c in components) for s, k in offsets.items()}
        orientation = _orientation_2d(all_corners)
        del all_corners

    metrics = {name: np.empty(n_cells) for name in METRICS}
    degenerate = np.empty(n_cells, dtype=bool)
    for first in range(0, n_cells, BLOCK_CELLS):
        block = slice(first, min(n_cells, first + BLOCK_CELLS))
        corner = {s: tuple(c[cells[block, k]] for c in components) for s, k in offsets.items()}
        block_centroid = tuple(c[block] for c in centroid)
        neighbour = {face: tuple(c[neighbour_cell[f, block]] for c in centroid_ext) for f, face in enumerate(faces)}
        if dim == 3:
            values, short = _hex_kernel(corner, block_centroid, neighbour, tolerance)
        else:
            values, short = _quad_kernel(corner, block_centroid, neighbour, tolerance, orientation)
        for name in METRICS:
            metrics[name][block] = values[name]
        degenerate[block] = short
    _apply_degenerate(metrics, degenerate)
    info = {"dim": dim, "nonfinite_nodes": nonfinite, "nonmanifold_faces": nonmanifold, "boundary_nodes": boundary_nodes}
    return metrics, degenerate, info


def cell_metrics_unstructured(points, cells) -> dict[str, np.ndarray]:
    """The seven per-cell metrics of an unstructured mesh.

    ``points``: (N, 3) or (N, 2) node coordinates (quads: z must be constant);
    ``cells``: (M, 8) hexahedra or (M, 4) quads, VTK corner order. Face neighbours (for
    non-orthogonality) are found from shared nodes. Returns arrays of length M keyed by ``METRICS``.
    """
    return _unstructured(points, cells)[0]


# ---------------------------------------------------------------------------------------------
# meshes read from files


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


def as_node_array(points, cells, dims) -> np.ndarray | None:
    """The node array of an unstructured mesh that is exactly meshgen's structured grid of ``dims``
    cells (same node order and connectivity), else None: such files take the fast path."""
    from meshgen.grid import cell_connectivity

    dims = tuple(int(n) for n in dims)
    node_shape = tuple(n + 1 for n in dims)
    dim = len(dims)
    if len(points) != int(np.prod(node_shape)) or cells.shape != (int(np.prod(dims)), 2 ** dim):
        return None
    if not np.array_equal(cells, cell_connectivity(node_shape)):
        return None
    if dim == 2 and points.shape[1] == 3:
        if np.any(points[:, 2] != points[0, 2]):
            return None
    return np.ascontiguousarray(points[:, :dim]).reshape(*node_shape, dim)


# ---------------------------------------------------------------------------------------------
# the report


def summarize(values: np.ndarray) -> dict:
    """mean, min, max, p01, p99 of ``values`` (floats); all None when there are none."""
    if values.size == 0:
        return {stat: None for stat in STATS}
    p01, p99 = np.percentile(values, [1.0, 99.0])
    return {
        "mean": float(np.mean(values)),
        "min": float(np.min(values)),
        "max": float(np.max(values)),
        "p01": float(p01),
        "p99": float(p99),
    }


def _assess(X_or_mesh):
    """Per-cell metrics of any accepted input, with what the report needs besides them."""
    # Non-finite coordinates are counted, reported and make their cells degenerate; the arithmetic
    # on them (inf - inf) must not also print NumPy's RuntimeWarnings beside meshgen's messages.
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        return _assess_quietly(X_or_mesh)


def _assess_quietly(X_or_mesh):
    from meshgen.deviation import grid_boundary_nodes

    if isinstance(X_or_mesh, np.ndarray):
        X = _check_node_array(X_or_mesh)
        metrics, degenerate, info = _structured(X)
        info["dim"] = X.shape[-1]
        info["boundary"] = lambda: grid_boundary_nodes(X)
        return metrics, degenerate, info
    skipped = {}
    if isinstance(X_or_mesh, tuple):
        points, cells = X_or_mesh
    else:
        points, cells, skipped = cells_for_quality(X_or_mesh)
    metrics, degenerate, info = _unstructured(points, cells)
    info["skipped"] = skipped
    info["boundary"] = lambda: (np.asarray(points, dtype=float)[info["boundary_nodes"], : info["dim"]], None)
    return metrics, degenerate, info


def quality_report(X_or_mesh, geometry=None) -> dict:
    """JSON-ready quality report of a mesh (the ``meshgen evaluate --json`` schema).

    ``X_or_mesh``: a node array ``(n1+1, n2+1[, n3+1], dim)``, a ``(points, cells)`` pair, or a
    ``meshio.Mesh`` (hexahedra, else quads; other cell types counted under ``skipped``).
    ``geometry``: a ``meshgen.geometry.Geometry``; adds ``boundary_deviation``.

    Keys: ``cells``, ``dim``, ``metrics`` ({name: {mean, min, max, p01, p99}}), ``inverted``
    ({count, fraction, degenerate}), ``valid``, ``valid_rule``, ``units`` and, when known,
    ``boundary_deviation``, ``skipped``, ``warnings``. Summaries leave degenerate cells out.
    """
    return _report(*_assess(X_or_mesh), geometry)


def _report(metrics, degenerate, info, geometry) -> dict:
    from meshgen.deviation import boundary_deviation

    dim = int(info["dim"])
    n_cells = int(len(degenerate))
    inverted = degenerate | ~(metrics["scaled_jacobian"] > 0.0)
    inverted_count = int(np.count_nonzero(inverted))
    shaped = ~degenerate
    report = {
        "cells": n_cells,
        "dim": dim,
        "cell_type": "hexahedron" if dim == 3 else "quad",
        "metrics": {name: summarize(metrics[name][shaped]) for name in METRICS},
        "inverted": {
            "count": inverted_count,
            "fraction": inverted_count / n_cells if n_cells else 0.0,
            "degenerate": int(np.count_nonzero(degenerate)),
        },
        "valid": bool(inverted_count <= VALID_FRACTION * n_cells),
        "valid_rule": VALID_RULE,
        "units": {"angles": "degrees", "non_orthogonality": "degrees"},
        "definitions": dict(DEFINITIONS),
    }
    warnings = []
    if info.get("nonfinite_nodes"):
        warnings.append(f"{info['nonfinite_nodes']} nodes have non-finite coordinates; their cells count as degenerate")
    if report["inverted"]["degenerate"]:
        warnings.append(
            f"{report['inverted']['degenerate']} degenerate cells (zero-length edge or non-finite node) "
            "count as inverted and are left out of the metric summaries"
        )
    if info.get("nonmanifold_faces"):
        warnings.append(f"{info['nonmanifold_faces']} faces are shared by more than two cells; treated as boundary faces")
    if info.get("skipped"):
        report["skipped"] = dict(info["skipped"])
    if geometry is not None:
        if geometry.dim != dim:
            raise MeshgenError(
                f"geometry '{geometry.name}' is {geometry.dim}D but the mesh is {dim}D: "
                "boundary deviation needs a geometry of the mesh's dimension"
            )
        boundary_points, guesses = info["boundary"]()
        deviation = boundary_deviation(boundary_points, geometry, parametric_guess=guesses)
        report["boundary_deviation"] = deviation
        if deviation.get("nonfinite_nodes"):
            warnings.append(
                f"{deviation['nonfinite_nodes']} boundary nodes are not finite: boundary deviation is undefined"
            )
    if warnings:
        report["warnings"] = warnings
    return report


def _format(value, digits=4) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return str(value)
    return f"{value:.{digits}g}"


def summary_lines(report: dict) -> list[str]:
    """A few lines for the terminal: the headline means, the worst cells, the verdict, the
    boundary deviation (what ``mesh``, ``train`` and ``compare`` print)."""
    m = report["metrics"]
    inv = report["inverted"]
    lines = [
        f"quality of {report['cells']} {report['cell_type']} cells: "
        f"min angle {_format(m['min_angle']['mean'], 3)} deg (worst {_format(m['min_angle']['min'], 3)}), "
        f"max angle {_format(m['max_angle']['mean'], 4)} deg (worst {_format(m['max_angle']['max'], 4)}), "
        f"equiangle skewness {_format(m['equiangle_skewness']['mean'], 3)}, "
        f"aspect ratio {_format(m['aspect_ratio']['mean'], 3)}",
        f"  centroid skewness {_format(m['centroid_skewness']['mean'], 3)}, "
        f"non-orthogonality {_format(m['non_orthogonality']['mean'], 3)} deg (worst {_format(m['non_orthogonality']['max'], 3)}), "
        f"scaled Jacobian min {_format(m['scaled_jacobian']['min'], 3)}",
        f"  inverted cells: {inv['count']} ({100 * inv['fraction']:.2f}%): "
        + ("valid" if report["valid"] else "NOT VALID")
        + " (valid: inverted <= 0.5% of cells)",
    ]
    deviation = report.get("boundary_deviation")
    if deviation:
        if deviation["max"] is None:
            lines.append("  boundary deviation: undefined (non-finite boundary nodes)")
        else:
            lines.append(
                f"  boundary deviation from '{deviation['geometry']}': max {deviation['max']:.3g} "
                f"({deviation['max_rel']:.3g} of L = {deviation['characteristic_length']:.4g}), mean {deviation['mean']:.3g}"
            )
    for warning in report.get("warnings", []):
        lines.append(f"  warning: {warning}")
    return lines


# ---------------------------------------------------------------------------------------------
# the mesh command's part: metrics as cell data, sidecar report


def sidecar_path(mesh_path) -> Path:
    """``<mesh>.quality.json`` beside a mesh file (the full file name, extension included)."""
    mesh_path = Path(mesh_path)
    return mesh_path.with_name(mesh_path.name + ".quality.json")


def write_json(path, data) -> Path:
    """Write ``data`` as indented JSON atomically (non-finite floats as null)."""
    from meshgen.atomic import atomic_path

    path = Path(path)
    text = json.dumps(_nulls(data), indent=2, allow_nan=False) + "\n"
    try:
        with atomic_path(path) as temporary:
            temporary.write_text(text)
    except OSError as exc:
        raise MeshgenError(f"could not write {path}: {exc.strerror or exc}") from exc
    return path


def _nulls(data):
    if isinstance(data, dict):
        return {k: _nulls(v) for k, v in data.items()}
    if isinstance(data, (list, tuple)):
        return [_nulls(v) for v in data]
    if isinstance(data, (float, np.floating)):
        return float(data) if np.isfinite(data) else None
    if isinstance(data, np.integer):
        return int(data)
    if isinstance(data, np.bool_):
        return bool(data)
    return data


def write_mesh_with_quality(path, X, geometry=None, metadata: dict | None = None, **write_options) -> dict:
    """Write node array ``X`` to ``path`` with the seven per-cell metrics as cell data (formats
    that carry cell data keep them), and the report plus ``metadata`` (geometry, params, method,
    ...) to ``<path>.quality.json``. ``write_options`` go to ``meshgen.formats.write_mesh``
    (``patches``, default the ``geometry``'s; ``format``; ``binary``). Returns the report (with
    ``quality_seconds``)."""
    from meshgen.formats import write_mesh

    if geometry is not None and "patches" not in write_options:
        from meshgen.patches import geometry_patches

        write_options["patches"] = geometry_patches(geometry)

    start = time.perf_counter()
    metrics, degenerate, info = _assess(_check_node_array(X))
    report = _report(metrics, degenerate, info, geometry)
    report["quality_seconds"] = time.perf_counter() - start
    written = write_mesh(path, X, cell_data=metrics, metadata=metadata, **write_options)
    write_json(sidecar_path(written), {"mesh": os.path.basename(written), **(metadata or {}), **report})
    return report


# ---------------------------------------------------------------------------------------------
# mesh files (meshgen evaluate)


def recorded_metadata(path, mesh) -> dict:
    """meshgen's metadata of a mesh file: what the file records (geometry, params, method, dims),
    else its ``<mesh>.quality.json`` sidecar (marked ``"source": "sidecar"``), else {}."""
    from meshgen.formats import metadata_of

    metadata = metadata_of(mesh)
    if metadata:
        return {**metadata, "source": "file"}
    sidecar = sidecar_path(path)
    if sidecar.is_file():
        try:
            recorded = json.loads(sidecar.read_text())
        except (OSError, ValueError):
            return {}
        if isinstance(recorded, dict):
            return {**recorded, "source": "sidecar"}
    return {}


def evaluate_file(path, geometry=None, params: dict | None = None, mesh=None) -> dict:
    """Quality report of a mesh file (any format ``meshgen.formats.read_mesh`` reads), with
    ``file`` and ``structured`` keys added.

    ``geometry``: a name or plugin path, a Geometry, or None for the geometry the file (or its
    sidecar) records; ``params`` override the geometry's parameters. A file that is meshgen's own
    structured grid takes the structured path. ``mesh``: the file as ``read_mesh(path)`` returned
    it, for a caller that needs it too (read once). MeshgenError when nothing can be evaluated.
    """
    from meshgen.errors import GeometryError
    from meshgen.formats import read_mesh
    from meshgen.geometry import load_geometry

    path = Path(path)
    if not path.exists():
        raise MeshgenError(f"mesh file {path} does not exist")
    if path.is_file() and path.stat().st_size == 0 and path.suffix.lower() != ".foam":
        raise MeshgenError(f"mesh file {path} is empty")
    if mesh is None:
        mesh = read_mesh(path)
    try:
        points, cells, skipped = cells_for_quality(mesh)
    except MeshgenError as exc:
        raise MeshgenError(f"{path}: {exc}") from None
    metadata = recorded_metadata(path, mesh)
    if metadata.get("source") == "sidecar" and (metadata.get("cells") != len(cells) or metadata.get("mesh") != path.name):
        metadata = {}  # a sidecar of another mesh that once had this name
    notes = []
    source = "--geometry"
    if isinstance(geometry, str):
        geometry = load_geometry(geometry, params)
    elif geometry is not None and params:
        geometry = geometry.with_params(**params)
    elif geometry is None and metadata.get("geometry"):
        source = f"recorded in the {'mesh file' if metadata['source'] == 'file' else 'sidecar ' + sidecar_path(path).name}"
        try:
            geometry = load_geometry(str(metadata["geometry"]), {**metadata.get("params", {}), **(params or {})})
        except GeometryError as exc:
            notes.append(f"recorded geometry '{metadata['geometry']}' is not available ({exc}); pass --geometry for boundary deviation")
            geometry = None
    elif params:
        raise MeshgenError(f"--param needs --geometry: {path} records no geometry")
    dims = metadata.get("dims")
    X = None
    if isinstance(dims, list) and len(dims) in (2, 3) and all(isinstance(n, int) and n > 0 for n in dims):
        X = as_node_array(points, cells, dims)
    try:
        metrics, degenerate, info = _assess(X if X is not None else (points, cells))
    except MeshgenError as exc:
        raise MeshgenError(f"{path}: {exc}") from None
    if degenerate.all():
        raise MeshgenError(
            f"{path}: nothing to evaluate: all {len(degenerate)} cells are degenerate "
            "(zero-length edges or non-finite coordinates)"
        )
    info["skipped"] = skipped
    if geometry is not None and geometry.dim != info["dim"] and source != "--geometry":
        notes.append(f"recorded geometry '{geometry.name}' is {geometry.dim}D but the mesh is {info['dim']}D; no boundary deviation")
        geometry = None
    report = _report(metrics, degenerate, info, geometry)
    if "boundary_deviation" in report:
        report["boundary_deviation"]["source"] = source
    if notes:
        report["warnings"] = report.get("warnings", []) + notes
    for key in ("method", "dims"):
        if key in metadata:
            report.setdefault("recorded", {})[key] = metadata[key]
    return {"file": str(path), "structured": X is not None, **report}
