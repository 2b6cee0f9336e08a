"""Cell kernels: the per-cell metrics of design notes §7 on one block of cells.

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
the other cells, so they are never NaN. A mesh is valid when none of its cells is inverted (a tolerance
is a gate the user sets: ``--fail-if "inverted.percent>0.5"``).

Everything is vectorised over cells; cells are processed in blocks of about 16 000 so that the
temporaries stay in cache (about 3x faster than whole-array passes at 1e6 cells). The structured
path (node arrays) and the unstructured one (points + connectivity, face neighbours found from
shared nodes) run the same kernel on the same corner coordinates, so they agree exactly.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "BLOCK_CELLS",
    "DEFINITIONS",
    "DEGENERATE_TOLERANCE",
    "HEX_CORNER",
    "HEX_FACES",
    "HEX_FACE_CORNERS",
    "METRICS",
    "QUAD_CORNER",
    "QUAD_FACES",
    "QUAD_FACE_CORNERS",
    "STATS",
    "VALID_FRACTION",
    "VALID_RULE",
    "WORST",
    "cross_2d",
    "hex_kernel",
    "quad_kernel",
    "vector_difference",
]

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
VALID_FRACTION = 0.0  # strict: one inverted cell makes a mesh invalid
VALID_RULE = "no inverted cell (inverted: scaled Jacobian <= 0 at a corner, or degenerate)"
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


def vector_difference(a, b):
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


def cross_2d(a, b):
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
    d = vector_difference(neighbour_centroid, centroid)
    inside = np.isfinite(sum(d))  # one test for all components: a NaN or inf anywhere shows in the sum
    d = tuple(np.where(inside, p, q) for p, q in zip(d, boundary_direction))
    return _unit(d)[0]


# ---------------------------------------------------------------------------------------------
# the kernels: one block of cells, corners given as component tuples of equal-shaped arrays


def hex_kernel(corner, centroid, neighbour_centroid, tolerance):
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
            edge = vector_difference(corner[tuple(high)], corner[tuple(low)])
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

        normal = _cross(vector_difference(node(1, 1), node(0, 0)), vector_difference(node(0, 1), node(1, 0)))
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
        largest_cosine,
        smallest_cosine,
        reflex_cosine,
        any_reflex,
        aspect_ratio,
        centroid_alignment,
        face_alignment,
        scaled_jacobian,
    ), degenerate


def quad_kernel(corner, centroid, neighbour_centroid, tolerance, orientation):
    """Metrics of a block of quadrilaterals in the plane (see ``hex_kernel``); ``orientation`` is
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
            edge = vector_difference(corner[tuple(high)], corner[tuple(low)])
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
    areas = (cross_2d(u0[0], u1[0]), cross_2d(u0[0], u1[1]), cross_2d(u0[1], u1[1]), cross_2d(u0[1], u1[0]))
    largest_cosine = np.maximum(np.maximum(cosines[0], cosines[1]), np.maximum(cosines[2], cosines[3]))
    smallest_cosine = np.minimum(np.minimum(cosines[0], cosines[1]), np.minimum(cosines[2], cosines[3]))
    smallest_area = np.minimum(np.minimum(areas[0], areas[1]), np.minimum(areas[2], areas[3]))
    largest_area = np.maximum(np.maximum(areas[0], areas[1]), np.maximum(areas[2], areas[3]))
    # Reflex corner: a corner area of the other sign than the quad's area at its centre (diagonals).
    centre_area = cross_2d(vector_difference(corner[(1, 1)], corner[(0, 0)]), vector_difference(corner[(0, 1)], corner[(1, 0)]))
    reflex = np.where(centre_area >= 0.0, smallest_area < 0.0, largest_area > 0.0)
    scaled_jacobian = smallest_area if orientation > 0 else -largest_area

    principal = [_unit(axis_sum[axis])[0] for axis in range(2)]
    centroid_alignment = face_alignment = None
    for axis, side in QUAD_FACES:
        along = u1[side] if axis == 0 else u0[side]  # the face is the edge across the normal axis
        # |n . e| with n the edge's in-plane normal is |along x e|.
        centroid_cosine = np.abs(cross_2d(along, principal[axis]))
        towards_neighbour = _neighbour_direction(neighbour_centroid[(axis, side)], centroid, principal[axis])
        face_cosine = np.abs(cross_2d(along, towards_neighbour))
        if centroid_alignment is None:
            centroid_alignment, face_alignment = centroid_cosine, face_cosine
        else:
            centroid_alignment = np.minimum(centroid_alignment, centroid_cosine)
            face_alignment = np.minimum(face_alignment, face_cosine)

    reflex_cosine = np.where(reflex, smallest_cosine, -2.0)
    return _finish(
        largest_cosine, smallest_cosine, reflex_cosine, reflex, aspect_ratio, centroid_alignment, face_alignment, scaled_jacobian
    ), degenerate


def _finish(
    largest_cosine, smallest_cosine, reflex_cosine, any_reflex, aspect_ratio, centroid_alignment, face_alignment, scaled_jacobian
):
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
