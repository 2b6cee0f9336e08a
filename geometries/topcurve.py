"""Box [0, Lx] x [0, Ly] x [0, H] whose top face is the doubly curved surface

    z = H + A sin(pi x / Lx) sin(pi y / Ly),

a dome (A > 0) or a dent (A < 0) that meets the four flat side walls at z = H. The map is
x = Lx xi, y = Ly eta, z = zeta * top(x, y): linear in zeta, so TFI reproduces it everywhere and
its Jacobian Lx Ly top(x, y) is positive whenever the top stays above the floor (H + min(A, 0) > 0).
Volume: Lx Ly (H + 4 A / pi^2).
"""

import numpy as np

from meshgen.errors import GeometryError

name = "topcurve"
dim = 3
description = "Box length x width x height, its top curved to z = height + amplitude sin(pi x/length) sin(pi y/width)"
axes = (
    "along x, inlet to outlet (flow)",
    "across, between the sides (spanwise, y)",
    "floor to top (wall-normal, z)",
)  # what each --dims number counts
params = {"length": 2.0, "width": 1.0, "height": 1.0, "amplitude": 0.3}
# A channel along x under a curved roof: in at x = 0, out at x = length, flat floor, symmetric sides.
patches = {
    "xi0": ("inlet", "patch"),
    "xi1": ("outlet", "patch"),
    "eta0": ("sides", "symmetry"),
    "eta1": ("sides", "symmetry"),
    "zeta0": ("floor", "wall"),
    "zeta1": ("top", "wall"),
}


def boundary(points, length, width, height, amplitude):
    """(N, 3) points on the unit cube's boundary -> (N, 3) points on the box's surface."""
    if min(length, width, height) <= 0 or height + min(amplitude, 0.0) <= 0:
        raise GeometryError(
            f"geometry 'topcurve': length, width, height must be positive and height + amplitude > 0 "
            f"(got length={length:g}, width={width:g}, height={height:g}, amplitude={amplitude:g})"
        )
    xi, eta, zeta = points[:, 0], points[:, 1], points[:, 2]
    top = height + amplitude * np.sin(np.pi * xi) * np.sin(np.pi * eta)
    return np.column_stack([length * xi, width * eta, zeta * top])
