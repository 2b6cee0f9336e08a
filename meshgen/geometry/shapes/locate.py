"""Points of the unit square located in a triangulation of it, and the surface point there.

A bucket grid over the square lists, per cell, the triangles whose bounding box meets it; a
query tests the triangles of its cell (vectorised over the queries, one candidate slot at a time)
and keeps the one where its smallest barycentric coordinate is largest. The barycentric
coordinates are clipped to [0, 1] and renormalised, so the point returned lies on a triangle of
the surface whatever the round-off.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SquareLocator", "build_locator"]


@dataclass(frozen=True)
class SquareLocator:
    """A triangulation of the unit square (``uv`` (n, 2), ``triangles`` (m, 3)) with a bucket
    grid of ``cells`` x ``cells``: ``order`` the triangle of each (cell, triangle) pair sorted by
    cell, ``start`` (cells^2 + 1,) each cell's first pair; ``origin``, ``inverse`` the affine
    maps to barycentric coordinates per triangle."""

    uv: np.ndarray
    triangles: np.ndarray
    cells: int
    order: np.ndarray
    start: np.ndarray
    origin: np.ndarray
    inverse: np.ndarray

    def barycentric(self, query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The triangle holding each point of ``query`` (N, 2) in [0, 1]^2 and its barycentric
        coordinates (N, 3) (non-negative, summing to 1)."""
        query = np.clip(np.asarray(query, dtype=float), 0.0, 1.0)
        cell_xy = np.minimum((query * self.cells).astype(np.int64), self.cells - 1)
        cell = cell_xy[:, 0] * self.cells + cell_xy[:, 1]
        first, count = self.start[cell], self.start[cell + 1] - self.start[cell]
        best_tri = np.zeros(len(query), dtype=np.int64)
        best_score = np.full(len(query), -np.inf)
        best_weights = np.zeros((len(query), 3))
        for slot in range(int(count.max()) if len(count) else 0):
            rows = np.flatnonzero((count > slot) & (best_score < 0.0))
            if len(rows) == 0:
                break
            tri = self.order[first[rows] + slot]
            local = np.einsum("nij,nj->ni", self.inverse[tri], query[rows] - self.origin[tri])
            weights = np.column_stack([1.0 - local.sum(axis=1), local])
            score = weights.min(axis=1)
            better = score > best_score[rows]
            rows, tri, weights, score = rows[better], tri[better], weights[better], score[better]
            best_tri[rows], best_score[rows], best_weights[rows] = tri, score, weights
        weights = np.clip(best_weights, 0.0, 1.0)
        weights /= weights.sum(axis=1, keepdims=True)
        return best_tri, weights

    def evaluate(self, values: np.ndarray, query: np.ndarray) -> np.ndarray:
        """The piecewise-linear interpolant of per-vertex ``values`` (n, d) at ``query`` (N, 2)."""
        tri, weights = self.barycentric(query)
        return np.einsum("nk,nkd->nd", weights, values[self.triangles[tri]])


def build_locator(uv: np.ndarray, triangles: np.ndarray) -> SquareLocator:
    """The bucket grid of a triangulation of the unit square (about two triangles per cell)."""
    uv = np.asarray(uv, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64)
    cells = max(1, int(np.sqrt(len(triangles) / 2.0)))
    corners = uv[triangles]  # (m, 3, 2)
    low = np.clip((corners.min(axis=1) * cells).astype(np.int64), 0, cells - 1)
    high = np.clip((corners.max(axis=1) * cells).astype(np.int64), 0, cells - 1)
    span = high - low + 1
    counts = span[:, 0] * span[:, 1]
    tri = np.repeat(np.arange(len(triangles)), counts)
    local = np.arange(len(tri)) - np.repeat(np.cumsum(counts) - counts, counts)
    i = low[tri, 0] + local // span[tri, 1]
    j = low[tri, 1] + local % span[tri, 1]
    cell = i * cells + j
    sort = np.argsort(cell, kind="stable")
    start = np.searchsorted(cell[sort], np.arange(cells * cells + 1))
    origin = corners[:, 0]
    edges = np.stack([corners[:, 1] - origin, corners[:, 2] - origin], axis=2)  # columns: b - a, c - a
    det = edges[:, 0, 0] * edges[:, 1, 1] - edges[:, 0, 1] * edges[:, 1, 0]
    det = np.where(np.abs(det) > 1e-300, det, 1e-300)
    inverse = np.empty_like(edges)
    inverse[:, 0, 0], inverse[:, 1, 1] = edges[:, 1, 1] / det, edges[:, 0, 0] / det
    inverse[:, 0, 1], inverse[:, 1, 0] = -edges[:, 0, 1] / det, -edges[:, 1, 0] / det
    return SquareLocator(uv, triangles, cells, tri[sort], start, origin, inverse)
