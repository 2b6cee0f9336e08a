"""Twisted flower prism: the five-petal cross-section r(t) = R (1 + a cos 5t), turned by a total
angle tau (degrees) along its axis z = L zeta.

The unit square's boundary maps to the flower curve by angle t, uniform along each edge, in four
arcs between four of the five petal tips: the square's corners (0, 0), (1, 0), (1, 1), (0, 1) sit at
t = 216, 288, 72, 144 degrees, so the edge xi = 1 spans the petal at t = 0 (144 degrees) and the
other edges 72 degrees each. Corners on petal tips matter: a square corner mapped to a concave
point of the curve (a valley between petals, where uniform 90-degree arcs would put one) gives an
inverted corner cell for any amplitude above about 0.06. With corners on tips, the Coons patch
(TFI) of the four arcs fills the section without folding for a <= 0.3.

The section at height z is that patch rotated by tau * zeta: a rotation is linear, so TFI of the
whole prism reproduces this map exactly, and the twist leaves every section's area, hence the
volume, unchanged: pi R^2 (1 + a^2 / 2) * L.
"""

import numpy as np

from meshgen.errors import GeometryError
from meshgen.methods.tfi import transfinite

name = "flower"
dim = 3
description = "Prism of five-petal section r = radius (1 + amplitude cos 5t) along z, twisted by twist degrees over its length"
axes = ("across the section", "across the section", "along the axis z, inlet to outlet (flow)")  # what each --dims number counts
params = {"radius": 1.0, "amplitude": 0.2, "length": 2.0, "twist": 90.0}
# The flow runs along the prism's axis; its side is a wall.
patches = {
    "zeta0": ("inlet", "patch"),
    "zeta1": ("outlet", "patch"),
    "xi0": ("wall", "wall"),
    "xi1": ("wall", "wall"),
    "eta0": ("wall", "wall"),
    "eta1": ("wall", "wall"),
}

# Angles (radians) of the square's corners (0, 0), (1, 0), (1, 1), (0, 1), increasing counterclockwise.
CORNER_ANGLES = np.radians([216.0, 288.0, 432.0, 504.0])
MAX_AMPLITUDE = 0.3  # above it the Coons-filled section folds near the long edge


def square_boundary_angle(xi, eta):
    """Angle t (radians) of points of the unit square's boundary: linear along each edge between
    the corners' CORNER_ANGLES, counterclockwise."""
    c0, c1, c2, c3 = CORNER_ANGLES
    on = lambda t, side: np.isclose(t, side, rtol=0.0, atol=1e-14)  # noqa: E731
    return np.select(
        [on(eta, 0.0), on(xi, 1.0), on(eta, 1.0)],
        [c0 + xi * (c1 - c0), c1 + eta * (c2 - c1), c3 + xi * (c2 - c3)],
        default=c0 + 2 * np.pi + eta * (c3 - c0 - 2 * np.pi),  # xi = 0, from (0, 0) up to (0, 1)
    )


def boundary(points, radius, amplitude, length, twist):
    """(N, 3) points on the unit cube's boundary -> (N, 3) points on the twisted prism's surface."""
    if radius <= 0 or length <= 0 or not 0 <= amplitude <= MAX_AMPLITUDE:
        raise GeometryError(
            f"geometry 'flower': need radius > 0, length > 0 and 0 <= amplitude <= {MAX_AMPLITUDE:g} "
            f"(got radius={radius:g}, amplitude={amplitude:g}, length={length:g})"
        )

    def flower(square_points):
        t = square_boundary_angle(square_points[:, 0], square_points[:, 1])
        r = radius * (1.0 + amplitude * np.cos(5 * t))
        return np.column_stack([r * np.cos(t), r * np.sin(t)])

    # Side faces: the flower's arcs reproduced; caps: the Coons-filled section.
    xy = transfinite(flower, [points[:, 0], points[:, 1]])
    turn = np.radians(twist) * points[:, 2]
    cos, sin = np.cos(turn), np.sin(turn)
    x = cos * xy[:, 0] - sin * xy[:, 1]
    y = sin * xy[:, 0] + cos * xy[:, 1]
    return np.column_stack([x, y, length * points[:, 2]])
