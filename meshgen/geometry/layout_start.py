"""The start of a face's surface-grid solve (``meshgen.geometry.layout``): the inverse of the discrete
harmonic coordinates of the surface.

The Winslow surface grid is the inverse of the map whose two coordinates are harmonic on the
surface (Laplace-Beltrami), with the computational coordinates as their boundary values. That is
two linear solves, whatever the surface's twist or the face map's distortion: here with the
cotangent Laplacian of the surface triangulated on a start grid (the Coons patch of the face's
edge parameters), after which each node's computational coordinates, and linear interpolation
over them, give the face parameters of the grid nodes. The result is the Winslow grid up to the
discretisation error of the start grid, a start from which Newton's method converges where the
Coons patch itself is too far (a nearly degenerate face map, such as a strongly lobed section's
Coons-filled cap).
"""

from __future__ import annotations

import numpy as np

__all__ = ["CANDIDATES", "harmonic_start", "lift"]


def lift(axis: int, side: int, U: np.ndarray) -> np.ndarray:
    """Face parameters U (..., 2) of the face ``t[axis] = side`` -> cube points (..., 3)."""
    a, b = (d for d in range(3) if d != axis)
    points = np.empty(U.shape[:-1] + (3,))
    points[..., axis] = side
    points[..., a], points[..., b] = U[..., 0], U[..., 1]
    return points


CANDIDATES = 16  # triangles (nearest by centroid) searched for the one holding a grid node


def _triangles(shape: tuple) -> np.ndarray:
    """Node indices (T, 3) of the tensor grid of ``shape`` nodes, two triangles per quadrilateral."""
    index = np.arange(shape[0] * shape[1]).reshape(shape)
    a, b, c, d = index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def _cotangent_laplacian(X: np.ndarray, shape: tuple):
    """Sparse cotangent Laplacian (n, n) of the surface X (n, 3) triangulated on the tensor grid
    of ``shape`` nodes (two triangles per quadrilateral)."""
    from scipy import sparse

    triangles = _triangles(shape)
    rows, cols, vals = [], [], []
    for k in range(3):
        corner, i, j = triangles[:, k], triangles[:, (k + 1) % 3], triangles[:, (k + 2) % 3]
        e1, e2 = X[i] - X[corner], X[j] - X[corner]
        weight = 0.5 * (e1 * e2).sum(-1) / np.maximum(np.linalg.norm(np.cross(e1, e2), axis=-1), 1e-300)  # cot / 2
        rows += [i, j, i, j]
        cols += [j, i, i, j]
        vals += [-weight, -weight, weight, weight]
    size = shape[0] * shape[1]
    return sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(size, size))


def harmonic_start(boundary, axis: int, side: int, U: np.ndarray, coords) -> np.ndarray:
    """Face parameters (n_p, n_q, 2) of the inverse harmonic grid of the face ``t[axis] = side``
    on the tensor grid of ``coords`` (t_p, t_q): ``U`` is the start grid (its sides are kept and
    give the boundary values), ``boundary`` the geometry's map. ``U`` itself is returned where the
    discrete harmonic coordinates fold so that some node has no preimage."""
    from scipy.sparse.linalg import spsolve
    from scipy.spatial import cKDTree

    t_p, t_q = (np.asarray(c, dtype=float) for c in coords)
    shape = U.shape[:-1]
    laplacian = _cotangent_laplacian(boundary(lift(axis, side, U).reshape(-1, 3)), shape)
    inner = np.zeros(shape, dtype=bool)
    inner[1:-1, 1:-1] = True
    inner = inner.ravel()
    P, Q = np.meshgrid(t_p, t_q, indexing="ij")
    harmonic = np.stack([P.ravel(), Q.ravel()], axis=1)  # boundary values: the computational coordinates
    rhs = -(laplacian[inner][:, ~inner] @ harmonic[~inner])
    system = laplacian[inner][:, inner].tocsc()
    harmonic[inner] = np.column_stack([spsolve(system, rhs[:, c]) for c in range(2)])
    start = np.array(U, dtype=float)
    # Linear interpolation of the start's parameters over the harmonic coordinates, at the grid's
    # computational coordinates: the start grid's own triangle (in harmonic coordinates) that
    # holds each target, among those nearest by centroid, and its barycentric weights.
    triangles = _triangles(shape)
    corners = harmonic[triangles]  # (T, 3, 2)
    tree = cKDTree(corners.mean(axis=1))
    targets = np.stack([P[1:-1, 1:-1].ravel(), Q[1:-1, 1:-1].ravel()], axis=1)
    result = np.full(targets.shape, np.nan)
    missing = np.arange(len(targets))
    for count in (CANDIDATES, 16 * CANDIDATES):  # the few nodes in long thin triangles search wider
        found, weights, chosen = _locate(corners, tree, targets[missing], min(count, len(triangles)))
        values = start.reshape(-1, 2)[triangles[chosen]]
        result[missing[found]] = np.einsum("nk,nkc->nc", weights, values)
        missing = missing[~found]
        if not len(missing):
            start[1:-1, 1:-1] = result.reshape(start[1:-1, 1:-1].shape)
            return start
    return start  # a node with no preimage: the discrete harmonic coordinates fold


def _locate(corners: np.ndarray, tree, targets: np.ndarray, count: int):
    """The triangle of ``corners`` (T, 3, 2) holding each of ``targets`` (N, 2), searched among the
    ``count`` nearest by centroid (``tree``): (found (N,) bool, barycentric weights (found, 3),
    triangle indices (found,))."""
    candidates = tree.query(targets, k=count)[1].reshape(len(targets), -1)  # (N, K)
    edge1 = corners[candidates, 1] - corners[candidates, 0]
    edge2 = corners[candidates, 2] - corners[candidates, 0]
    offset = targets[:, None, :] - corners[candidates, 0]
    det = edge1[..., 0] * edge2[..., 1] - edge1[..., 1] * edge2[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        w1 = (offset[..., 0] * edge2[..., 1] - offset[..., 1] * edge2[..., 0]) / det
        w2 = (edge1[..., 0] * offset[..., 1] - edge1[..., 1] * offset[..., 0]) / det
    weights = np.stack([1.0 - w1 - w2, w1, w2], axis=-1)  # (N, K, 3)
    inside = np.all(weights >= -1e-12, axis=-1) & np.isfinite(det) & (det != 0)
    found = inside.any(axis=1)
    first = inside.argmax(axis=1)[found]
    rows = np.flatnonzero(found)
    return found, weights[rows, first], candidates[rows, first]
