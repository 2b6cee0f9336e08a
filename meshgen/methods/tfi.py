"""Transfinite interpolation (Gordon-Hall, linear blending; design notes §4).

The interpolant is the Boolean sum of the linear projectors along each parametric axis,

    X = sum over non-empty axis subsets S of (-1)^(|S|+1) sum over sides s in {0,1}^S
        prod_{d in S} L_{s_d}(t_d) F(t with t_d = s_d for d in S),    L_0(t) = 1 - t, L_1(t) = t,

which in 3D is the six face terms, minus the twelve edge terms, plus the eight vertex terms, and
in 2D the Coons patch. It reproduces the boundary map F exactly.
"""

from __future__ import annotations

import itertools

import numpy as np

from meshgen.errors import MeshgenError
from meshgen.geometry import cube

__all__ = [
    "add_face_terms",
    "blending",
    "boundary_faces",
    "check_axes",
    "face_terms",
    "face_values",
    "parametric_grid",
    "tfi",
    "transfinite",
    "transfinite_on_grid",
]


def parametric_grid(dims) -> list[np.ndarray]:
    """Uniform parametric node coordinates: one array of ``n + 1`` values in [0, 1] per cell count."""
    return [np.linspace(0.0, 1.0, int(n) + 1) for n in dims]


def transfinite(boundary, coords, power: int = 1) -> np.ndarray:
    """Gordon-Hall interpolant of ``boundary`` at parametric coordinates ``coords`` (``power``: of
    the blending functions, :func:`blending`; 1, linear, for TFI).

    ``boundary``: ``(N, dim) -> (N, dim)`` map of the unit cube's boundary.
    ``coords``: ``dim`` mutually broadcastable arrays (t_1, ..., t_dim) in [0, 1]; e.g. three
    arrays of shape (N,) for scattered points, or shapes (n1, 1, 1), (1, n2, 1), (1, 1, n3) for a
    tensor grid, where each face term is then evaluated on its face alone.
    Returns the physical points, shape ``broadcast(coords) + (dim,)``.
    """
    coords = [np.asarray(c, dtype=float) for c in coords]
    dim = len(coords)
    shape = np.broadcast_shapes(*(c.shape for c in coords))
    terms = []  # (sign, blending weight, the term's points on the boundary as broadcast arrays)
    for size in range(1, dim + 1):
        sign = 1.0 if size % 2 else -1.0
        for axes in itertools.combinations(range(dim), size):
            for sides in itertools.product((0.0, 1.0), repeat=size):
                weight = np.ones(())
                fixed = list(coords)
                for axis, side in zip(axes, sides):
                    weight = weight * blending(coords[axis], int(side), power)
                    fixed[axis] = np.asarray(side)
                terms.append((sign, weight, np.broadcast_arrays(*fixed)))
    # One call of the boundary map for the points of all terms: a plugin's cost is mostly per call
    # when the terms are small (edges, vertices, a training grid's faces).
    points = np.concatenate([np.stack([a.reshape(-1) for a in fixed], axis=1) for _, _, fixed in terms])
    images = boundary(points)
    result = np.zeros(shape + (dim,))
    start = 0
    for sign, weight, fixed in terms:
        count = fixed[0].size
        result += sign * weight[..., None] * images[start : start + count].reshape(*fixed[0].shape, dim)
        start += count
    return result


def boundary_faces(coords):
    """The parametric points of each face of the tensor grid of ``coords``: a list of
    (index, points) per face, ``index`` selecting the face's nodes of X (a tuple of slices and one
    integer), ``points`` (face nodes, d) on the unit cube's boundary."""
    return [(face.node_index, face.points(coords)) for face in cube.faces(len(coords))]


def transfinite_on_grid(boundary, coords, out: np.ndarray | None = None) -> np.ndarray:
    """Gordon-Hall TFI on the tensor grid of ``coords``, whose first and last
    values must be 0 and 1, added to ``out`` (n1, .., d) when given, else returned.

    The boundary map is called once, on the grid's face nodes; :func:`face_terms` and
    :func:`add_face_terms` do the rest.
    """
    return add_face_terms(face_terms(face_values(boundary, coords), coords), coords, out)


FACE_VALUE_POINTS = 1 << 18


def face_values(boundary, coords) -> list[np.ndarray]:
    """``boundary`` ((N, d) -> (N, d), point by point) at the face nodes of the tensor grid of
    ``coords``: per face, in :func:`boundary_faces` order, an array (face nodes..., d). The points
    go through in calls of at most ``FACE_VALUE_POINTS``: a boundary map's temporaries are some
    times its output, which at 1000^3 nodes (6e6 face nodes) would be gigabytes in one call."""
    coords = [np.asarray(c, dtype=float) for c in coords]
    values = []
    shape = tuple(len(c) for c in coords)
    for face, (_index, points) in zip(cube.faces(len(coords)), boundary_faces(coords)):
        face_shape = tuple(n for d, n in enumerate(shape) if d != face.axis)
        parts = [boundary(points[start : start + FACE_VALUE_POINTS]) for start in range(0, len(points), FACE_VALUE_POINTS)]
        values.append(np.concatenate(parts).reshape(*face_shape, -1))
    return values


def blending(t, side: int, power: int = 1):
    """The blending function of a side: L_0(t) = (1 - t)^power, L_1(t) = t^power. Power 1 is
    Gordon-Hall's linear blending (TFI); any power keeps L_s(s) = 1 and L_s(1 - s) = 0, so the
    Boolean sum still reproduces the data on every face, while a higher power confines the
    interpolant of data on a face to a layer next to it (about 1 / power of the axis deep)."""
    t = np.asarray(t, dtype=float)
    weight = t if side else 1.0 - t
    return weight if power == 1 else weight**power


def face_terms(face_values, coords, power: int = 1) -> list:
    """The blended face terms of the TFI of data given at the face nodes of the tensor grid of
    ``coords`` (first and last values 0 and 1 on every axis); ``power``: the blending functions'
    (:func:`blending`; 1 for TFI), the same as given to :func:`add_face_terms` with the terms.

    ``face_values``: per face, in :func:`boundary_faces` order (axis-major, side-minor), the data
    at its nodes, shape (face nodes..., d) or (face nodes, d) in C order. Returns [(axis, side, D)],
    D of shape (the grid's shape without ``axis``) + (d,): the Boolean sum
    P1 + P2 (I - P1) + P3 (I - P1)(I - P2) taken one axis at a time. With U_a the interpolant of
    the first a axes, U_a = U_(a-1) + (1 - t_a) D_a0 + t_a D_a1, where D_as = F - U_(a-1) on the
    face t_a = s. Each D is face-sized (O(n^2) memory in 3D), so the whole grid sees six blended
    face terms (2D: four) instead of the 26 face, edge and vertex terms of the direct form; the TFI
    of any data on the faces (the boundary map, a network's boundary error) is then
    :func:`add_face_terms` on any block of the grid.
    """
    coords = [np.asarray(c, dtype=float) for c in coords]
    dim = len(coords)
    if any(c[0] != 0.0 or c[-1] != 1.0 for c in coords):
        raise ValueError("transfinite_on_grid needs node coordinates from 0 to 1 on every axis")
    shape = tuple(len(c) for c in coords)
    terms = []  # (axis, side, D on the face grid: shape without the axis, + (dim,))
    for values, face in zip(face_values, cube.faces(dim)):
        axis, side = face.axis, face.side
        face_shape = tuple(n for d, n in enumerate(shape) if d != axis)
        values = np.asarray(values, dtype=float).reshape(*face_shape, -1).copy()
        end = 0 if side == 0 else -1
        for earlier, earlier_side, D in [t for t in terms if t[0] < axis]:  # minus U_(axis-1) on this face
            # D lacks its own (earlier) axis, so this axis is D's axis - 1; on the face, the earlier
            # axis keeps its number, this one being later.
            restricted = np.expand_dims(np.take(D, end, axis=axis - 1), earlier)
            weight = blending(coords[earlier], earlier_side, power)
            values -= _along(weight, earlier, dim - 1) * restricted
        terms.append((axis, side, values))
    return terms


def add_face_terms(terms, coords, out: np.ndarray | None = None, block=None, power: int = 1) -> np.ndarray:
    """Add the TFI of :func:`face_terms` ``terms`` (made on the grid of ``coords`` with the same
    blending ``power``) to ``out``, or
    return it: on the whole grid, or with ``block`` (one slice per axis, steps of 1) on that block
    of its nodes only, ``out`` then of the block's shape (m1, .., d). A block-wise caller makes
    the terms once (face-sized) and evaluates any block of the grid from them; each node sees the
    same arithmetic whatever the block, so a mesh made block by block equals the whole-grid one
    bit for bit."""
    coords = [np.asarray(c, dtype=float) for c in coords]
    dim = len(coords)
    block = tuple(block) if block is not None else (slice(None),) * dim
    shape = tuple(len(np.arange(len(c))[b]) for c, b in zip(coords, block))
    result = np.zeros(shape + (terms[0][2].shape[-1],)) if out is None else out
    for axis, side, D in terms:
        weight = blending(coords[axis][block[axis]], side, power)
        on_block = D[tuple(b for d, b in enumerate(block) if d != axis)]
        result += _along(weight, axis, dim) * np.expand_dims(on_block, axis)
    return result


def _along(values, axis: int, dim: int) -> np.ndarray:
    """1D ``values`` shaped to broadcast along ``axis`` of a (.., dim)-component grid of ``dim`` axes."""
    return np.asarray(values).reshape([-1 if d == axis else 1 for d in range(dim)] + [1])


def check_axes(geometry, coords) -> None:
    """MeshgenError unless there is one 1D coordinate array (or cell count) per axis of ``geometry``."""
    if len(coords) != geometry.dim:
        raise MeshgenError(f"{len(coords)} axes given for the {geometry.dim}D geometry '{geometry.name}'")


def tfi(geometry, dims, coords: list[np.ndarray] | None = None) -> np.ndarray:
    """Transfinite-interpolation mesh of ``geometry``.

    ``dims``: cells per axis (n1, n2[, n3]). ``coords``: optional 1D parametric node positions per
    axis (default uniform), e.g. clustered towards a wall.
    Returns the node array X, shape ``(n1+1, n2+1[, n3+1], dim)``, float64.
    """
    if coords is None:
        coords = parametric_grid(dims)
    check_axes(geometry, coords)
    dim = len(coords)
    coords = [np.asarray(c, dtype=float) for c in coords]
    if all(c[0] == 0.0 and c[-1] == 1.0 for c in coords):
        return transfinite_on_grid(geometry.boundary, coords)  # six face terms instead of 26
    # A grid that does not reach the cube's faces (a sub-block): the direct Boolean sum.
    axes = [c.reshape([-1 if d == a else 1 for d in range(dim)]) for a, c in enumerate(coords)]
    return transfinite(geometry.boundary, axes)
