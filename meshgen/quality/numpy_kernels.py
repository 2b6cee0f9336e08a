"""The per-cell quality metrics of a structured node array in plain NumPy: the vectorised
definition (design notes §7), block by block of ``BLOCK_CELLS`` cells.

Two uses: the compiled kernels (``meshgen.quality.compiled``) are tested against it, and small
meshes take it instead of them (``meshgen.quality.structured``): importing numba and loading the
compiled kernels costs a process about a second, more than NumPy needs for 5e5 cells."""

from __future__ import annotations

import numpy as np

from meshgen.quality.kernels import (
    BLOCK_CELLS,
    DEGENERATE_TOLERANCE,
    HEX_CORNER,
    HEX_FACES,
    METRICS,
    QUAD_CORNER,
    QUAD_FACES,
    WORST,
)

__all__ = ["finite_extent", "numpy_cell_metrics"]


def finite_extent(points):
    """``meshgen.quality.compiled.finite_extent`` in NumPy: per component (min, max) of the finite
    rows of ``points`` (N, d), and the number of rows with a non-finite coordinate."""
    finite = np.isfinite(points).all(axis=1)
    bad = int(len(points) - np.count_nonzero(finite))
    if bad == len(points):
        return np.full(points.shape[1], np.inf), np.full(points.shape[1], -np.inf), bad
    kept = points[finite] if bad else points
    return kept.min(axis=0), kept.max(axis=0), bad


def degenerate_tolerance(components):
    finite = np.ones(components[0].shape, dtype=bool)
    for c in components:
        finite &= np.isfinite(c)
    if not finite.any():
        return 0.0
    return DEGENERATE_TOLERANCE * np.sqrt(sum(float(np.ptp(c[finite])) ** 2 for c in components))


def orientation_2d(corner) -> float:
    area = _cross2(_sub(corner[(1, 1)], corner[(0, 0)]), _sub(corner[(0, 1)], corner[(1, 0)]))
    return 1.0 if float(np.nansum(area)) >= 0.0 else -1.0


def apply_degenerate(metrics, degenerate):
    for name, worst in WORST.items():
        metrics[name][degenerate] = worst
    sj = metrics["scaled_jacobian"]
    sj[degenerate] = np.minimum(np.where(np.isfinite(sj[degenerate]), sj[degenerate], 0.0), 0.0)


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
    shortest_edge = longest_edge = None
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
            longest_edge = length if longest_edge is None else np.maximum(longest_edge, length)
        mean_length[axis] = (lengths[0] + lengths[1] + lengths[2] + lengths[3]) * 0.25
    degenerate = ~((shortest_edge > tolerance) & np.isfinite(longest_edge))  # np.minimum keeps NaN

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
        largest_cosine,
        smallest_cosine,
        reflex_cosine,
        any_reflex,
        aspect_ratio,
        centroid_alignment,
        face_alignment,
        scaled_jacobian,
    ), degenerate


def _quad_kernel(corner, centroid, neighbour_centroid, tolerance, orientation):
    """Metrics of a block of quadrilaterals in the plane (see ``_hex_kernel``); ``orientation`` is
    +1 or -1, the sign of the mesh's total area: corners turning the other way are inverted."""
    unit_edge, axis_sum, mean_length = [{}, {}], [None, None], [None, None]
    shortest_edge = longest_edge = None
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
            longest_edge = length if longest_edge is None else np.maximum(longest_edge, length)
        mean_length[axis] = (lengths[0] + lengths[1]) * 0.5
    degenerate = ~((shortest_edge > tolerance) & np.isfinite(longest_edge))
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


def _reference(X, tolerance=None, orientation=None):
    """Per-cell metrics (C order of cells) and the degenerate mask of node array ``X``.

    ``tolerance`` (degenerate-edge length) and ``orientation`` (2D: +1 or -1) default to those of
    ``X`` itself; a block of a larger mesh passes the whole mesh's, so its cells get the values they
    get in the whole."""
    X = np.asarray(X, dtype=float)
    dim = X.shape[-1]
    node_shape = X.shape[:-1]
    cell_shape = tuple(n - 1 for n in node_shape)
    n_cells = int(np.prod(cell_shape))
    components = tuple(np.ascontiguousarray(X[..., c]) for c in range(dim))
    own_tolerance = degenerate_tolerance(components)
    tolerance = own_tolerance if tolerance is None else tolerance
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
    if orientation is None:
        orientation = orientation_2d(all_corners) if dim == 2 else 1.0
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
    apply_degenerate(metrics, degenerate)
    return metrics, degenerate


def numpy_cell_metrics(X, tolerance=None, orientation=None):
    """(metrics dict, degenerate mask) of node array ``X`` (n1+1, n2+1[, n3+1], dim), cells in C
    order; ``tolerance`` and ``orientation`` as in ``meshgen.quality.structured.structured_metrics``."""
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        return _reference(X, tolerance, orientation)
