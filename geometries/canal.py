"""Semicircular canal: a tube of circular cross-section (radius r) bent along a half circle
(radius R), an arch standing on the plane z = 0 with its two open ends there.

Cross-section: the disk of radius r, the unit square's boundary mapped to the circle uniformly in
angle, one quarter per edge with the square's corners at 45 + k * 90 degrees, so that the Coons
patch (TFI) of the four arcs fills the disk without folding. In the section, a runs along the
bend's radial direction e_r = (cos phi, 0, sin phi) and b along y; the section is swept by the
angle phi = pi * zeta along the centre line R (cos phi, 0, sin phi):

    x(xi, eta, zeta) = (R + a) e_r(phi) + b e_y,   (a, b) = Coons patch of the circle at (xi, eta).

(e_r, e_y, e_phi) is right-handed, so the map is orientation preserving. The caps (zeta = 0, 1)
are Coons-filled disks. Volume (Pappus): pi r^2 * pi R. Needs r < R.
"""

import numpy as np

from meshgen.errors import GeometryError
from meshgen.methods.tfi import transfinite

name = "canal"
dim = 3
description = "Semicircular canal: a tube of tube_radius bent along a half circle of bend_radius (an arch on z = 0)"
axes = (
    "across the tube (along the bend radius)",
    "across the tube (along y)",
    "along the bend, inlet to outlet (flow)",
)  # what each --dims number counts
params = {"tube_radius": 0.5, "bend_radius": 2.0}
# The flow runs along the tube: in at zeta = 0, out at zeta = 1; the tube's surface is a wall.
patches = {
    "zeta0": ("inlet", "patch"),
    "zeta1": ("outlet", "patch"),
    "xi0": ("wall", "wall"),
    "xi1": ("wall", "wall"),
    "eta0": ("wall", "wall"),
    "eta1": ("wall", "wall"),
}


# Angles (radians) of the square's corners (0, 0), (1, 0), (1, 1), (0, 1), increasing counterclockwise:
# a quarter turn per edge, as in an O-grid of the disk.
CORNER_ANGLES = np.radians([225.0, 315.0, 405.0, 495.0])


def square_boundary_angle(xi, eta):
    """Angle (radians) of points of the unit square's boundary: linear along each edge between
    the corners' CORNER_ANGLES, counterclockwise."""
    c0, c1, c2, c3 = CORNER_ANGLES
    on = lambda t, side: np.isclose(t, side, rtol=0.0, atol=1e-14)  # noqa: E731
    return np.select(
        [on(eta, 0.0), on(xi, 1.0), on(eta, 1.0)],
        [c0 + xi * (c1 - c0), c1 + eta * (c2 - c1), c3 + xi * (c2 - c3)],
        default=c0 + 2 * np.pi + eta * (c3 - c0 - 2 * np.pi),  # xi = 0, from (0, 0) up to (0, 1)
    )


def boundary(points, tube_radius, bend_radius):
    """(N, 3) points on the unit cube's boundary -> (N, 3) points on the canal's surface."""
    if not 0 < tube_radius < bend_radius:
        raise GeometryError(
            f"geometry 'canal': need 0 < tube_radius < bend_radius (got tube_radius={tube_radius:g}, bend_radius={bend_radius:g})"
        )

    def circle(square_points):
        angle = square_boundary_angle(square_points[:, 0], square_points[:, 1])
        return tube_radius * np.column_stack([np.cos(angle), np.sin(angle)])

    # Side faces: the circle's arcs reproduced; caps: the Coons-filled disk.
    ab = transfinite(circle, [points[:, 0], points[:, 1]])
    phi = np.pi * points[:, 2]
    radial = bend_radius + ab[:, 0]
    return np.column_stack([radial * np.cos(phi), ab[:, 1], radial * np.sin(phi)])
