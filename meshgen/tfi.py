"""Transfinite interpolation (Gordon-Hall, linear blending; DESIGN section 4).

The interpolant is the Boolean sum of the linear projectors along each parametric axis,

    X = sum over non-empty axis subsets S of (-1)^(|S|+1) sum over sides s in {0,1}^S
        prod_{d in S} L_{s_d}(t_d) F(t with t_d = s_d for d in S),    L_0(t) = 1 - t, L_1(t) = t,

which in 3D is the six face terms, minus the twelve edge terms, plus the eight vertex terms, and
in 2D the Coons patch. It reproduces the boundary map F exactly.
"""

from __future__ import annotations

import itertools

import numpy as np

from meshgen import cube
from meshgen.errors import MeshgenError


def parametric_grid(dims) -> list[np.ndarray]:
    """Uniform parametric node coordinates: one array of ``n + 1`` values in [0, 1] per cell count."""
    return [np.linspace(0.0, 1.0, int(n) + 1) for n in dims]


def transfinite(boundary, coords) -> np.ndarray:
    """Gordon-Hall interpolant of ``boundary`` at parametric coordinates ``coords``.

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
                    weight = weight * (coords[axis] if side else 1.0 - coords[axis])
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

    The Boolean sum P1 + P2 (I - P1) + P3 (I - P1)(I - P2) taken one axis at a time: with U_a the
    interpolant of the first a axes, U_a = U_(a-1) + (1 - t_a) D_a0 + t_a D_a1, where
    D_as = F - U_(a-1) on the face t_a = s. Each D is face-sized, so the whole grid sees six
    blended face terms (2D: four) instead of the 26 face, edge and vertex terms of the direct form.
    """
    coords = [np.asarray(c, dtype=float) for c in coords]
    faces = boundary_faces(coords)
    images = boundary(np.concatenate([points for _, points in faces]))
    shape = tuple(len(c) for c in coords)
    corrections = face_corrections(images, coords)
    whole = tuple(slice(0, n) for n in shape)
    return blend_face_corrections(corrections, coords, whole, out=out)


def face_corrections(face_values: np.ndarray, coords) -> list:
    """The face terms D_as of the axis-by-axis Boolean sum (see ``transfinite_on_grid``) from the
    values of the map on the faces of the tensor grid of ``coords`` (first and last values 0 and 1).

    ``face_values``: (sum of face node counts, d), the faces in the order of ``boundary_faces``.
    Returns [(axis, side, D)], D of the face's grid shape + (d,): O(n^2) memory in 3D. The TFI of
    any function given on the faces (the boundary map; a network's boundary error) is then
    ``blend_face_corrections`` on any block of the grid, block by block.
    """
    coords = [np.asarray(c, dtype=float) for c in coords]
    dim = len(coords)
    if any(c[0] != 0.0 or c[-1] != 1.0 for c in coords):
        raise ValueError("transfinite_on_grid needs node coordinates from 0 to 1 on every axis")
    shape = tuple(len(c) for c in coords)
    corrections = []  # (axis, side, D on the face grid: shape without the axis, + (dim,))
    start = 0
    for face in cube.faces(dim):
        axis, side = face.axis, face.side
        face_shape = tuple(n for d, n in enumerate(shape) if d != axis)
        count = int(np.prod(face_shape))
        values = np.array(face_values[start : start + count].reshape(*face_shape, -1), dtype=float)
        start += count
        end = 0 if side == 0 else -1
        for earlier, earlier_side, D in [c for c in corrections if c[0] < axis]:  # minus U_(axis-1) on this face
            # D lacks its own (earlier) axis, so this axis is D's axis - 1; on the face, the earlier
            # axis keeps its number, this one being later.
            restricted = np.expand_dims(np.take(D, end, axis=axis - 1), earlier)
            weight = coords[earlier] if earlier_side else 1.0 - coords[earlier]
            values -= _along(weight, earlier, dim - 1) * restricted
        corrections.append((axis, side, values))
    return corrections


def blend_face_corrections(corrections, coords, block, out: np.ndarray | None = None) -> np.ndarray:
    """sum over faces of (1 - t_a or t_a) D_as on the nodes ``block`` (one slice per axis, step 1)
    of the tensor grid of ``coords``: the TFI there, added to ``out`` (block shape + (d,)) when
    given, else returned. Each node sees the same arithmetic whatever the block, so a mesh made
    block by block equals the whole-grid one bit for bit."""
    dim = len(coords)
    shape = tuple(len(range(*s.indices(len(c)))) for s, c in zip(block, coords))
    result = np.zeros(shape + (corrections[0][2].shape[-1],)) if out is None else out
    for axis, side, D in corrections:
        t = np.asarray(coords[axis], dtype=float)[block[axis]]
        weight = t if side else 1.0 - t
        face_block = tuple(s for d, s in enumerate(block) if d != axis)
        result += _along(weight, axis, dim) * np.expand_dims(D[face_block], axis)
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
