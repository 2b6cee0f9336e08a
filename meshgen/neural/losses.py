"""Training points and the two losses (design notes §6).

L1 = mean over interior points of |R|^2, R the scale-free Winslow residual (``winslow``).
L2 = mean over boundary points of w |e|^2 with e = N(xi) - B(xi), B the normalised boundary map,
and w = 1 + c |e| the surface-point weight (c = 1 in the paper), detached: it steers the fit
towards the worst points and takes no gradient itself.

``method.boundary_error: relative`` measures e in units of the boundary's local size instead,
e = (N(xi) - B(xi)) / h(xi) with h (:func:`boundary_local_size`) the shortest tangent of B along
the face at xi: the error as a fraction of the local cell size, times the cells per side. It makes
L2 scale-free like L1: a thin part of the geometry (a tube whose cross-section is a tenth of the
bounding box) asks for the same fit in cells as a fat one, where in normalised units its error
would count a hundred times less than the cells it distorts.
"""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["TANGENT_STEP", "SIZE_FLOOR", "sample_interior", "sample_boundary", "pde_loss", "boundary_local_size", "boundary_loss"]


TANGENT_STEP = 1e-4  # parametric step of the central differences of boundary_local_size
SIZE_FLOOR = 1e-2  # boundary_local_size: at least this fraction of the median (a pole cannot take L2 over)


def sample_interior(count: int, dim: int, generator: torch.Generator | None = None) -> torch.Tensor:
    """``count`` points uniform in the open unit cube, (count, dim) float32."""
    return torch.rand((count, dim), generator=generator)


def sample_boundary(count: int, dim: int, generator: torch.Generator | None = None) -> torch.Tensor:
    """``count`` points uniform on the unit cube's boundary (every face has area 1, so a face is
    drawn uniformly among the 2 dim and a point uniformly on it), (count, dim) float32."""
    points = torch.rand((count, dim), generator=generator)
    faces = torch.randint(0, 2 * dim, (count,), generator=generator)
    points[torch.arange(count), faces // 2] = (faces % 2).to(points.dtype)
    return points


def pde_loss(residual: torch.Tensor) -> torch.Tensor:
    """L1: mean over points of the squared residual norm. ``residual``: (..., dim)."""
    return residual.square().sum(-1).mean()


def boundary_local_size(boundary, points: np.ndarray, images: np.ndarray | None = None) -> np.ndarray:
    """The boundary map's local size at cube-boundary ``points`` (N, d) float64: the shortest of its
    tangent vectors |dB/dxi_t| over the axes t along which the point can move and stay on the
    boundary (the axes of its face; on an edge, of both faces), by one-sided differences of step
    ``TANGENT_STEP`` (towards the middle of the axis: one evaluation of B per axis). Units of B per
    unit parametric length: the local cell size times the cells per side. Floored at
    ``SIZE_FLOOR`` times the median. Returns (N,) float64.

    ``boundary``: (N, d) -> (N, d), vectorised (a Problem's normalised boundary map); ``images``:
    its values at ``points`` when the caller has them (saves one call)."""
    points = np.asarray(points, dtype=float)
    count, dim = points.shape
    on_face = (points == 0.0) | (points == 1.0)  # (N, d)
    # moving along an axis keeps the point on the boundary iff another coordinate is at 0 or 1
    movable = [np.flatnonzero(np.delete(on_face, axis, axis=1).any(axis=1)) for axis in range(dim)]
    steps = []
    for axis, rows in enumerate(movable):
        moved = points[rows].copy()
        step = np.where(moved[:, axis] < 0.5, TANGENT_STEP, -TANGENT_STEP)
        moved[:, axis] += step
        steps.append((moved, step))
    moved_images = boundary(np.concatenate([moved for moved, _ in steps]))
    images = boundary(points) if images is None else np.asarray(images, dtype=float)
    size, start = np.full(count, np.inf), 0
    for rows, (_moved, step) in zip(movable, steps):
        tangent = (moved_images[start : start + len(rows)] - images[rows]) / step[:, None]
        size[rows] = np.minimum(size[rows], np.linalg.norm(tangent, axis=1))
        start += len(rows)
    return np.maximum(size, SIZE_FLOOR * np.median(size))


def boundary_loss(predicted: torch.Tensor, target: torch.Tensor, point_weight_scale: float = 1.0, size=None):
    """L2 and the per-point distances.

    ``predicted``, ``target``: (N, dim) in normalised units. ``point_weight_scale`` c sets the
    surface-point weights w = 1 + c |error| (0 switches them off). ``size``: None (the error in
    normalised units), or (N,) the boundary's local size at the points
    (:func:`boundary_local_size`): the error is divided by it (``boundary_error: relative``).
    Returns (L2, distance) with distance (N,) detached, in the error's units.
    """
    error = predicted - target
    if size is not None:
        error = error / size[:, None]
    squared = error.square().sum(-1)
    distance = squared.detach().sqrt()
    weights = 1.0 + point_weight_scale * distance
    return (weights * squared).mean(), distance
