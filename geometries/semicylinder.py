"""Half-cylinder of radius R and length L, the reference shape of design notes §3.

Cross-section: the half-disk x^2 + y^2 <= R^2, y >= 0, parametrised by (xi, eta) as in the
``semidisk`` geometry; z = L * zeta. The side faces map the square's edges; the caps
(zeta = 0, 1) are the Coons patch of those four edges.
"""

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import transfinite

name = "semicylinder"
dim = 3
description = "Half-cylinder of radius R and length L (half-disk section x^2+y^2<=R^2, y>=0, along z)"
axes = (
    "across the flat face (x)",
    "from the flat face up to the arc",
    "along the axis z, inlet to outlet (flow)",
)  # what each --dims number counts
params = {"radius": 1.0, "length": 2.0}
# The flow runs along z: in at z = 0, out at z = length; the flat face y = 0 is a symmetry plane.
patches = {
    "zeta0": ("inlet", "patch"),
    "zeta1": ("outlet", "patch"),
    "xi0": ("wall", "wall"),
    "eta1": ("wall", "wall"),
    "xi1": ("wall", "wall"),
    "eta0": ("symmetry", "symmetry"),
}

_section = load_geometry("semidisk", check=False)


def boundary(points, radius, length):
    """(N, 3) points on the unit cube's boundary -> (N, 3) points on the half-cylinder's surface."""
    if radius <= 0 or length <= 0:
        raise GeometryError(
            f"geometry 'semicylinder': radius and length must be positive (got radius={radius:g}, length={length:g})"
        )
    section = _section.with_params(radius=radius)
    # The Coons patch reproduces the section's edges on the side faces and fills the caps.
    xy = transfinite(section.boundary, [points[:, 0], points[:, 1]])
    return np.column_stack([xy, length * points[:, 2]])
