"""Half-disk x^2 + y^2 <= R^2, y >= 0: the semicylinder's cross-section (design notes §3)."""

import numpy as np

from meshgen.errors import GeometryError

name = "semidisk"
dim = 2
description = "Half-disk x^2 + y^2 <= R^2, y >= 0 (the semicylinder's cross-section)"
axes = ("along the diameter (x)", "from the diameter up to the arc")  # what each --dims number counts
params = {"radius": 1.0}
# The arc is a wall; the diameter y = 0 is a symmetry plane.
patches = {"xi0": ("wall", "wall"), "eta1": ("wall", "wall"), "xi1": ("wall", "wall"), "eta0": ("symmetry", "symmetry")}


def boundary(points, radius):
    """(N, 2) points on the unit square's boundary -> (N, 2) points of the half-disk's boundary.

    eta = 0 is the diameter (x = 2 xi - 1); the other three edges share the arc, uniform in angle:
    xi = 0 from pi to 3pi/4, eta = 1 from 3pi/4 to pi/4, xi = 1 from pi/4 to 0.
    """
    if radius <= 0:
        raise GeometryError(f"geometry 'semidisk': radius must be positive, got {radius:g}")
    xi, eta = points[:, 0], points[:, 1]
    on_diameter = np.isclose(eta, 0.0, rtol=0.0, atol=1e-14)
    angle = np.where(
        np.isclose(xi, 0.0, rtol=0.0, atol=1e-14),
        np.pi - eta * np.pi / 4,
        np.where(np.isclose(xi, 1.0, rtol=0.0, atol=1e-14), eta * np.pi / 4, 3 * np.pi / 4 - xi * np.pi / 2),
    )
    x = np.where(on_diameter, 2.0 * xi - 1.0, np.cos(angle))
    y = np.where(on_diameter, 0.0, np.sin(angle))
    return radius * np.stack([x, y], axis=1)
