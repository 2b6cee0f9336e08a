"""Training points and the two losses (DESIGN section 6).

L1 = mean over interior points of |R|^2, R the scale-free Winslow residual (``winslow``).
L2 = mean over boundary points of w |N(xi) - B(xi)|^2, B the normalised boundary map and
w = 1 + c |N(xi) - B(xi)| the surface-point weight (c = 1 in the paper), detached: it steers
the fit towards the worst points and takes no gradient itself.
"""

from __future__ import annotations

import torch


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


def boundary_loss(predicted: torch.Tensor, target: torch.Tensor, point_weight_scale: float = 1.0):
    """L2 and the per-point distances.

    ``predicted``, ``target``: (N, dim) in normalised units. ``point_weight_scale`` c sets the
    surface-point weights w = 1 + c |error| (0 switches them off).
    Returns (L2, distance) with distance (N,) detached.
    """
    squared = (predicted - target).square().sum(-1)
    distance = squared.detach().sqrt()
    weights = 1.0 + point_weight_scale * distance
    return (weights * squared).mean(), distance
