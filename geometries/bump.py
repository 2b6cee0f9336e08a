"""Channel [0, L] x [0, H] with a smooth bump on its lower wall (2D):

    y = h cos^2(pi (x - c) / w)   for |x - c| < w / 2,   y = 0 elsewhere,

a bump of height h (h < 0: a dip) and base width w centred at x = c, which meets the flat wall
with zero slope.
Lower wall uniform in x (x = L xi), upper wall y = H, inlet x = 0, outlet x = L.
Area: L H - h w / 2.
"""

import numpy as np

from meshgen.errors import GeometryError

name = "bump"
dim = 2
description = "Channel length x height with a cos^2 bump (bump_height, bump_width, at x = bump_center) on its lower wall"
axes = (
    "along the channel (x), inlet to outlet (flow)",
    "lower wall to upper wall (wall-normal, y)",
)  # what each --dims number counts
params = {"length": 3.0, "height": 1.0, "bump_height": 0.25, "bump_width": 1.0, "bump_center": 1.5}
# In at x = 0, out at x = length, between the bumped lower wall and the flat upper wall.
patches = {
    "xi0": ("inlet", "patch"),
    "xi1": ("outlet", "patch"),
    "eta0": ("lowerWall", "wall"),
    "eta1": ("upperWall", "wall"),
}


def lower_wall(x, bump_height, bump_width, bump_center):
    """Height of the lower wall at abscissae ``x`` (any shape)."""
    phase = np.pi * (x - bump_center) / bump_width
    return np.where(np.abs(phase) < np.pi / 2, bump_height * np.cos(phase) ** 2, 0.0)


def boundary(points, length, height, bump_height, bump_width, bump_center):
    """(N, 2) points on the unit square's boundary -> (N, 2) points of the channel's boundary.

    eta = 0: the bumped lower wall; eta = 1: the upper wall; xi = 0, 1: inlet and outlet, uniform in y.
    """
    if min(length, height, bump_width) <= 0 or bump_height >= height:
        raise GeometryError(
            f"geometry 'bump': length, height, bump_width must be positive and bump_height < height "
            f"(got length={length:g}, height={height:g}, bump_height={bump_height:g}, bump_width={bump_width:g})"
        )
    if bump_center - bump_width / 2 < 0 or bump_center + bump_width / 2 > length:
        raise GeometryError(
            f"geometry 'bump': the bump [{bump_center - bump_width / 2:g}, {bump_center + bump_width / 2:g}] "
            f"must lie inside the channel [0, {length:g}]"
        )
    xi, eta = points[:, 0], points[:, 1]
    x = length * xi
    floor = lower_wall(x, bump_height, bump_width, bump_center)
    # Every boundary point lies on the segment from the lower to the upper wall above its x
    # (the inlet and outlet have floor 0 there), so one formula covers all four edges.
    return np.column_stack([x, (1.0 - eta) * floor + eta * height])
