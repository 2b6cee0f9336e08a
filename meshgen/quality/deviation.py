"""Boundary deviation: how far the boundary nodes of a mesh lie from the geometry's true boundary.

The true boundary is the image of the unit cube's faces (2D: the unit square's edges) under the
geometry's boundary map. The distance of a node to it is found on that map itself, not on a
polygonal approximation of it, so it carries no discretisation error of its own:

1. Seed. A node of a structured block starts on its own face, at its index position (i/n1, ...).
   If the node lies on the boundary there (distance below 1e-10 of the characteristic length, the
   usual case for TFI and elliptic meshes), that is its distance: nothing else can be closer.
2. Coarse search. Otherwise (and for unstructured files, which have no index positions) every
   face is sampled on a 17 x 17 grid (2D: 65 points per edge); the nearest sample of each face
   gives a starting point, and every face that could hold a nearer point than the best sample
   (its nearest sample minus the face's sampling radius) becomes a candidate.
3. Projection. From each start, projected Gauss-Newton (finite-difference Jacobian of the map,
   box constraints of the face, backtracking) finds the nearest point of that face.

The distance reported is the smallest found. It is the distance to a point on the true boundary,
so never below the true distance, and equal to it to about 1e-12 of the characteristic length
when the nearest point lies in the basin of a candidate's start, which a 16 x 16 coarse grid per
face gives for any boundary that is smooth on that scale.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from meshgen.geometry import cube
from meshgen.geometry.block_nodes import global_numbering
from meshgen.geometry.cube import faces as cube_faces
from meshgen.geometry.layout import unsmoothed

__all__ = [
    "COARSE_INTERVALS",
    "FD_STEP",
    "ITERATIONS",
    "METHOD",
    "ON_BOUNDARY",
    "block_set_deviation",
    "boundary_deviation",
    "distance_to_boundary",
    "grid_boundary_nodes",
    "project_to_faces",
]

COARSE_INTERVALS = {3: 16, 2: 64}  # coarse samples per face parameter, minus one
ON_BOUNDARY = 1e-10  # relative to the characteristic length: a node this close needs no search
FD_STEP = 1e-7  # finite-difference step of the Jacobian, in face parameters
ITERATIONS = 200  # an upper bound: most points stop after a few
METHOD = "closest point on the geometry's boundary map: coarse search, then projected Gauss-Newton on each candidate face"


def _faces(dim: int):
    """(axis, side) of each face of the unit cube (square), and each face's parameter axes."""
    faces = [(face.axis, float(face.side)) for face in cube_faces(dim)]
    parameters = np.array([face.tangent_axes for face in cube_faces(dim)])
    return faces, parameters


def _lift(dim, face, uv):
    """Face ids (K,) and face parameters (K, dim-1) -> points on the cube's boundary (K, dim)."""
    faces, parameters = _faces(dim)
    axis = np.array([a for a, _ in faces])[face]
    side = np.array([s for _, s in faces])[face]
    rows = np.arange(len(face))
    cube = np.empty((len(face), dim))
    cube[rows, axis] = side
    cube[rows[:, None], parameters[face]] = uv
    return cube


def _damped_step(J, r, uv, damping):
    """Levenberg-Marquardt step (K, m) for min |S(uv) - p|^2 in the box [0, 1]^m: solve
    (J^T J + damping I) d = -J^T r; a coordinate at a bound whose step points out of the box is
    held there and the other one solved for alone."""
    m = uv.shape[1]
    g = [np.einsum("ij,ij->i", J[j], r) for j in range(m)]
    A = [[np.einsum("ij,ij->i", J[i], J[j]) for j in range(m)] for i in range(m)]

    def single(j):
        return -g[j] / (A[j][j] + damping)

    def blocked(step, j):
        return ((uv[:, j] <= 0.0) & (step < 0.0)) | ((uv[:, j] >= 1.0) & (step > 0.0))

    if m == 1:
        step = single(0)
        return np.where(blocked(step, 0), 0.0, step)[:, None]
    a, b, c = A[0][0] + damping, A[0][1], A[1][1] + damping
    det = a * c - b * b
    det = np.where(det > 0.0, det, np.finfo(float).tiny)
    d0 = -(c * g[0] - b * g[1]) / det
    d1 = -(a * g[1] - b * g[0]) / det
    hold0, hold1 = blocked(d0, 0), blocked(d1, 1)
    alone0, alone1 = single(0), single(1)
    alone0 = np.where(blocked(alone0, 0), 0.0, alone0)
    alone1 = np.where(blocked(alone1, 1), 0.0, alone1)
    d0 = np.where(hold0, 0.0, np.where(hold1, alone0, d0))
    d1 = np.where(hold1, 0.0, np.where(hold0, alone1, d1))
    return np.stack([d0, d1], axis=1)


def project_to_faces(points, face, uv, boundary_map, dim):
    """Nearest points of the given faces to ``points``, starting from face parameters ``uv``.

    ``points`` (K, dim); ``face`` (K,) face ids in the order of ``_faces``; ``uv`` (K, dim-1)
    starting parameters in [0, 1]; ``boundary_map`` maps (N, dim) cube-boundary points to (N, dim)
    physical ones. Levenberg-Marquardt with a finite-difference Jacobian: the damping grows on a
    failed step and shrinks on a good one, so it also gets through the points where a face's
    parametrisation degenerates (e.g. a corner of the square mapped onto a smooth arc).
    Returns (distances (K,), parameters (K, dim-1)).
    """
    m = dim - 1
    uv = np.clip(np.array(uv, dtype=float), 0.0, 1.0)
    surface = boundary_map(_lift(dim, face, uv))
    distance = np.linalg.norm(surface - points, axis=1)
    damping = np.full(len(points), np.nan)  # set from the first Jacobian, relative to its scale
    active = np.arange(len(points))
    for _ in range(ITERATIONS):
        if len(active) == 0:
            break
        f, u, p = face[active], uv[active], points[active]
        k = len(active)
        step = np.where(u < 0.5, FD_STEP, -FD_STEP)  # into the face, so probes stay on it
        probes = [u + step[:, j : j + 1] * np.eye(m)[j] for j in range(m)]
        probed = boundary_map(_lift(dim, np.tile(f, m), np.concatenate(probes)))
        s0 = surface[active]
        J = [(probed[j * k : (j + 1) * k] - s0) / step[:, j : j + 1] for j in range(m)]
        scale = sum(np.einsum("ij,ij->i", Jj, Jj) for Jj in J) + np.finfo(float).tiny
        # Stationary: the residual is normal to the face (projected gradient ~ 0). 1e-6 is above the
        # finite-difference error of J and, the distance being stationary there, changes it by
        # about 1e-12 of itself.
        r = s0 - p
        gradient = 0.0
        for j in range(m):
            g = np.einsum("ij,ij->i", J[j], r)
            g = np.where(((u[:, j] <= 0.0) & (g > 0.0)) | ((u[:, j] >= 1.0) & (g < 0.0)), 0.0, g)
            gradient = gradient + g * g
        moving = np.sqrt(gradient) > 1e-6 * np.sqrt(scale) * distance[active]
        if m == 2:
            # Where the face's parametrisation degenerates (J of rank 1, e.g. a square's corner
            # mapped onto a smooth arc) a zero gradient proves nothing: keep iterating there.
            a, b, c = (np.einsum("ij,ij->i", J[i], J[j]) for i, j in ((0, 0), (0, 1), (1, 1)))
            moving |= a * c - b * b <= 1e-6 * scale * scale
        active, f, u, p, r, s0, scale = (a[moving] for a in (active, f, u, p, r, s0, scale))
        J = [Jj[moving] for Jj in J]
        if len(active) == 0:
            break
        lam = np.where(np.isnan(damping[active]), 1e-6 * scale, damping[active])
        delta = _damped_step(J, r, u, lam)
        candidate = np.clip(u + delta, 0.0, 1.0)
        s = boundary_map(_lift(dim, f, candidate))
        d = np.linalg.norm(s - p, axis=1)
        better = d < distance[active]
        moved = np.abs(candidate - u).max(axis=1)
        good = active[better]
        uv[good], surface[good], distance[good] = candidate[better], s[better], d[better]
        damping[active] = np.where(better, lam / 4.0, lam * 8.0)
        # Also done: a step below round-off of the parameters, or damping so large no step is left.
        done = (moved <= 1e-14) | (~better & (lam > 1e12 * scale))
        active = active[~done]
    return distance, uv


def _face_samples(boundary_map, dim):
    """Coarse samples of every face: parameters (S, m), points (F, S, dim), and each face's
    sampling radius (F,): any point of a coarse patch lies within about half its longest diagonal
    of one of the patch's corners; 1.5x that for curvature."""
    faces, _ = _faces(dim)
    m, n = dim - 1, COARSE_INTERVALS[dim]
    t = np.linspace(0.0, 1.0, n + 1)
    grid = np.stack(np.meshgrid(*([t] * m), indexing="ij"), axis=-1).reshape(-1, m)
    face_ids = np.repeat(np.arange(len(faces)), len(grid))
    samples = boundary_map(_lift(dim, face_ids, np.tile(grid, (len(faces), 1)))).reshape(len(faces), len(grid), dim)
    if m == 2:
        patch = samples.reshape(len(faces), n + 1, n + 1, dim)
        diagonal = np.maximum(
            np.linalg.norm(patch[:, 1:, 1:] - patch[:, :-1, :-1], axis=-1),
            np.linalg.norm(patch[:, 1:, :-1] - patch[:, :-1, 1:], axis=-1),
        )
    else:
        diagonal = np.linalg.norm(np.diff(samples, axis=1), axis=-1)
    radius = 0.75 * diagonal.reshape(len(faces), -1).max(axis=1)
    return grid, samples, radius


def _nearest_sample(points, samples):
    """Index (K,) and distance (K,) of the nearest of ``samples`` (S, dim) to each point (K, dim)."""
    squared = np.einsum("ij,ij->i", samples, samples)
    index = np.empty(len(points), dtype=np.int64)
    distance = np.empty(len(points))
    chunk = max(1, 2_000_000 // len(samples))
    for first in range(0, len(points), chunk):
        p = points[first : first + chunk]
        d2 = p @ samples.T  # |p - s|^2 - |p|^2 = |s|^2 - 2 p.s, without temporaries
        d2 *= -2.0
        d2 += squared
        i = np.argmin(d2, axis=1)
        index[first : first + chunk] = i
        nearest = d2[np.arange(len(p)), i] + np.einsum("ij,ij->i", p, p)
        distance[first : first + chunk] = np.sqrt(np.maximum(nearest, 0.0))
    return index, distance


def _coarse_candidates(points, boundary_map, dim, upper, exclude, allowed=None):
    """Starting points for the projection: (point index, face, start parameters) triples, and
    an upper bound (K,) of each point's distance (its nearest coarse sample, or ``upper``).

    A face is searched for a point only if the point is within ``upper`` of the face's bounding
    box, and becomes a candidate if its nearest sample, less its sampling radius, is within the
    best bound. ``exclude`` (K,): a face per point already projected onto (-1: none).
    ``allowed`` (F,) bool: the faces that are boundary at all (None: every face)."""
    faces, _ = _faces(dim)
    grid, samples, radius = _face_samples(boundary_map, dim)
    n = COARSE_INTERVALS[dim]
    upper = np.array(upper, dtype=float)
    if not np.all(np.isfinite(upper)):
        # A cheap first bound from every fourth sample of every face.
        every = np.zeros([n + 1] * (dim - 1), dtype=bool)
        every[tuple(slice(None, None, 4) for _ in range(dim - 1))] = True
        _, bound = _nearest_sample(points, samples[:, every.reshape(-1)].reshape(-1, dim))
        upper = np.minimum(upper, bound)
    low = samples.min(axis=1) - radius[:, None]
    high = samples.max(axis=1) + radius[:, None]
    outside = np.maximum(np.maximum(low[None] - points[:, None], points[:, None] - high[None]), 0.0)
    searched = np.linalg.norm(outside, axis=2) <= upper[:, None] * (1 + 1e-9)
    searched &= np.arange(len(faces))[None, :] != np.asarray(exclude)[:, None]
    if allowed is not None:
        searched &= np.asarray(allowed, dtype=bool)[None, :]
    nearest = np.full((len(points), len(faces)), np.inf)
    start = np.zeros((len(points), len(faces)), dtype=np.int64)
    for f in range(len(faces)):
        rows = np.flatnonzero(searched[:, f])
        if len(rows):
            start[rows, f], nearest[rows, f] = _nearest_sample(points[rows], samples[f])
    best = np.minimum(upper, nearest.min(axis=1))
    # The sample distances are approximate (expanded squares): a small margin keeps ties in.
    point, face = np.nonzero(nearest - radius <= best[:, None] * (1 + 1e-9) + 1e-12 * radius.max())
    return point, face, grid[start[point, face]], best


def distance_to_boundary(points, geometry, parametric_guess=None, faces=None) -> np.ndarray:
    """Distance (K,) of each point (K, dim) to the geometry's true boundary; NaN for non-finite points.

    ``parametric_guess`` (K, dim): optional positions on the unit cube's boundary to start from
    (for the boundary nodes of a structured block: their index positions). ``faces``: the cube
    faces (names, e.g. ``("xi1", "zeta0")``) that make the boundary (a block of a block set: its
    patch faces, not its interfaces); None: all of them."""
    geometry = unsmoothed(geometry)  # the surface is the same for every boundary layout: use its own map
    points = np.asarray(points, dtype=float)
    dim = geometry.dim
    length = geometry.characteristic_length
    distance = np.full(len(points), np.inf)
    own_face = np.full(len(points), -1)
    finite = np.isfinite(points).all(axis=1)
    todo = np.flatnonzero(finite)
    if parametric_guess is not None and len(todo):
        guess = np.asarray(parametric_guess, dtype=float)[todo]
        on_face = (guess == 0.0) | (guess == 1.0)
        axis = np.argmax(on_face, axis=1)
        side = guess[np.arange(len(todo)), axis]
        face = 2 * axis + (side == 1.0)
        _, parameters = _faces(dim)
        uv = guess[np.arange(len(todo))[:, None], parameters[face]]
        distance[todo], _ = project_to_faces(points[todo], face, uv, geometry.boundary, dim)
        own_face[todo] = face
        todo = todo[distance[todo] > ON_BOUNDARY * length]
    allowed = None if faces is None else np.array([face.name in faces for face in cube_faces(dim)])
    if len(todo) and (allowed is None or allowed.any()):
        point, face, uv, bound = _coarse_candidates(points[todo], geometry.boundary, dim, distance[todo], own_face[todo], allowed)
        found, _ = project_to_faces(points[todo][point], face, uv, geometry.boundary, dim)
        np.minimum.at(bound, point, found)
        distance[todo] = np.minimum(distance[todo], bound)
    distance[~finite] = np.nan
    return distance


def grid_boundary_nodes(X):
    """Boundary nodes of a structured block: (points (K, dim), index positions (K, dim) on the
    unit cube's boundary), each node once."""
    node_shape = X.shape[:-1]
    dim = X.shape[-1]
    on_boundary = np.zeros(node_shape, dtype=bool)
    for axis in range(dim):
        index = [slice(None)] * dim
        for end in (0, -1):
            index[axis] = end
            on_boundary[tuple(index)] = True
    nodes = np.nonzero(on_boundary)
    positions = np.stack([i / (n - 1) for i, n in zip(nodes, node_shape)], axis=1)
    return X[nodes], positions


def boundary_deviation(points, geometry, parametric_guess=None) -> dict:
    """Max and mean distance of boundary nodes ``points`` (K, dim) from the true boundary of
    ``geometry``, absolute and relative to its characteristic length (JSON-ready dict).

    A node array may be given instead of points: its block-face nodes are used, seeded with their
    index positions. Non-finite nodes make the figures undefined (None), counted in ``nonfinite_nodes``.
    """
    points = np.asarray(points, dtype=float)
    if points.ndim == geometry.dim + 1 and parametric_guess is None:
        points, parametric_guess = grid_boundary_nodes(points)
    distance = distance_to_boundary(points, geometry, parametric_guess)
    nonfinite = int(np.count_nonzero(np.isnan(distance)))
    finite = distance[~np.isnan(distance)]
    return deviation_figures(
        len(distance), float(finite.sum()), float(finite.max()) if len(finite) else None, nonfinite, geometry
    )


def deviation_figures(nodes: int, total: float, largest, nonfinite: int, geometry) -> dict:
    """The ``boundary_deviation`` dict from the number of boundary ``nodes``, the ``total`` and
    ``largest`` distance of the finite ones and the count of ``nonfinite`` ones: a caller that
    measures the nodes in parts (``meshgen.quality.chunked``) adds these up and calls this once."""
    length = float(geometry.characteristic_length)
    undefined = nonfinite > 0 or nodes == 0
    largest = None if undefined else float(largest)
    mean = None if undefined else total / nodes
    return {
        "max": largest,
        "mean": mean,
        "max_rel": None if undefined else largest / length,
        "mean_rel": None if undefined else mean / length,
        "characteristic_length": length,
        "nodes": int(nodes),
        "nonfinite_nodes": nonfinite,
        "geometry": geometry.name,
        "params": dict(geometry.values),
        "method": METHOD,
    }


def block_set_deviation(block_set, Xs=None, points=None) -> dict:
    """The boundary deviation of a block set's mesh (``meshgen.geometry.blocks.BlockSet``): its true
    boundary is the union of the blocks' patch faces (an interface face is inside the domain).

    ``Xs``: the blocks' node arrays. Each patch face's nodes start on their own face at their
    parametric positions (the block set's coordinates where the shapes match, else the index
    positions); a node found off its own block's patch faces (an elliptic mesh's nodes slide in
    their planes, across the blocks' maps) is measured against every block's patch faces. A node
    on several blocks' faces is counted once. ``points`` (K, dim) instead: the boundary nodes of
    the merged mesh (a file without blocks), each measured against every block's patch faces.
    Distances are to points of the true boundary: never below the true distance."""
    names = cube.face_names(block_set.dim)
    faces_of = [tuple(face for face in names if (block, face) in block_set.patches) for block in range(len(block_set.names))]
    if Xs is None:
        points = np.asarray(points, dtype=float)
        distance = np.full(len(points), np.inf)
        pending = np.arange(len(points))
    else:
        numbering, count = global_numbering(block_set)
        points = np.full((count, block_set.dim), np.nan)
        distance, measured = np.full(count, np.nan), np.zeros(count, dtype=bool)
        for block, (X, ids, geometry, faces) in enumerate(zip(Xs, numbering, block_set.geometries, faces_of)):
            points[ids.reshape(-1)] = X.reshape(-1, block_set.dim)
            coords = block_set.coords[block]
            if tuple(len(t) for t in coords) != X.shape[:-1]:
                coords = [np.linspace(0.0, 1.0, n) for n in X.shape[:-1]]
            for name in faces:
                face = cube.face_named(name, block_set.dim)
                found = distance_to_boundary(
                    X[face.node_index].reshape(-1, block_set.dim), geometry, face.points(coords), faces=faces
                )
                where = ids[face.node_index].reshape(-1)
                distance[where] = np.fmin(distance[where], found)  # NaN only where every measure is NaN
                measured[where] = True
        keep = np.flatnonzero(measured)
        points, distance = points[keep], distance[keep]
        pending = np.flatnonzero(distance > ON_BOUNDARY * block_set.length)
    for geometry, faces in zip(block_set.geometries, faces_of):
        if faces and len(pending):
            distance[pending] = np.fmin(distance[pending], distance_to_boundary(points[pending], geometry, faces=faces))
    distance[~np.isfinite(points).all(axis=1)] = np.nan
    nonfinite = int(np.count_nonzero(np.isnan(distance)))
    finite = distance[~np.isnan(distance)]
    named = SimpleNamespace(characteristic_length=block_set.length, name=block_set.name, values=block_set.values)
    return deviation_figures(len(distance), float(finite.sum()), float(finite.max()) if len(finite) else None, nonfinite, named)
