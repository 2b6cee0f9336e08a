"""Straight round pipe of radius R and length L as an O-grid (meshgen.geometry.blocks): a square core block
and four blocks between the core and the wall, one per quarter of the circumference.

Cross-section: the core is the square |x|, |y| <= c with c = CORE * R; block ``east`` fills the
space between the core's side x = c and the wall arc from -45 to 45 degrees (xi from the core
outwards, eta counterclockwise), ``north``, ``west`` and ``south`` are the same block turned by 90,
180 and 270 degrees. z = L * zeta in every block: in at z = 0, out at z = L.
"""

import numpy as np

from meshgen.errors import GeometryError
from meshgen.methods.tfi import transfinite

name = "pipe"
dim = 3
description = "Straight round pipe of radius R and length L along z: O-grid of a core block and four wall blocks"
params = {"radius": 0.5, "length": 4.0}
dims_meaning = "N M A: cells around a quarter of the circumference (and across the core), across the wall layer, along the axis"
blocks = ("core", "east", "north", "west", "south")
RING = blocks[1:]
CORE = 0.45  # half-width of the core square, relative to the radius
# The core's sides bulge outwards (parabolas) so that they leave its corners turned by BULGE from
# the square's: the core's corner angle is then 90 + 2 BULGE degrees and the two wall blocks' angles
# there 135 - BULGE each, 120 degrees all three.
BULGE = np.radians(15.0)

interfaces = [("core", face, ring, "xi0") for face, ring in zip(("xi1", "eta1", "xi0", "eta0"), RING)] + [
    (RING[k], "eta1", RING[(k + 1) % 4], "eta0") for k in range(4)
]
_ends = {"zeta0": ("inlet", "patch"), "zeta1": ("outlet", "patch")}
block_patches = {"core": dict(_ends), **{ring: {"xi1": ("wall", "wall"), **_ends} for ring in RING}}


def characteristic_length(radius, length):
    return float(np.hypot(2 * radius, length))


def block_coords(dims, radius, length):
    """Uniform parametric nodes: the core N x N x A cells, each wall block M x N x A."""
    n, m, a = dims
    nodes = [np.linspace(0.0, 1.0, k + 1) for k in (n, m, a)]
    return {"core": [nodes[0], nodes[0], nodes[2]], **{ring: [nodes[1], nodes[0], nodes[2]] for ring in RING}}


def _core_side(s, c):
    """The core's side x = c bulged: points (x, y) for s in [-1, 1] along it (y = c s)."""
    return np.stack([c + 0.5 * c * np.tan(BULGE) * (1.0 - s**2), c * s], axis=1)


def _core_section(points, radius):
    """The core's boundary: each side of the square bulged (``_core_side`` turned)."""
    xi, eta = points[:, 0], points[:, 1]
    c = CORE * radius
    result = np.empty_like(points)
    sides = [  # (on this side, turn by quarters, position along the east side)
        (np.isclose(xi, 1.0), 0, 2.0 * eta - 1.0),
        (np.isclose(eta, 1.0), 1, 1.0 - 2.0 * xi),
        (np.isclose(xi, 0.0), 2, 1.0 - 2.0 * eta),
        (np.isclose(eta, 0.0), 3, 2.0 * xi - 1.0),
    ]
    for on, quarter, s in sides:
        cos, sin = np.cos(quarter * np.pi / 2), np.sin(quarter * np.pi / 2)
        side = _core_side(s[on], c)
        result[on] = side @ np.array([[cos, -sin], [sin, cos]]).T
    return result


def _east_section(points, radius):
    """The east block's cross-section boundary: xi = 0 the core's side, xi = 1 the wall arc,
    eta = 0 and 1 the straight lines from the core's corners to the wall at -45 and 45 degrees."""
    xi, eta = points[:, 0], points[:, 1]
    c = CORE * radius
    inner = _core_side(2.0 * eta - 1.0, c)
    angle = (eta - 0.5) * np.pi / 2
    outer = radius * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    return (1.0 - xi)[:, None] * inner + xi[:, None] * outer


def _turned(section, quarter):
    cos, sin = np.cos(quarter * np.pi / 2), np.sin(quarter * np.pi / 2)
    rotation = np.array([[cos, -sin], [sin, cos]])

    def turned(points, radius):
        return section(points, radius) @ rotation.T

    return turned


_SECTIONS = {"core": _core_section, **{ring: _turned(_east_section, k) for k, ring in enumerate(RING)}}


def boundary(block, points, radius, length):
    """(N, 3) points on the unit cube's boundary -> (N, 3) points on block ``block``'s boundary."""
    if radius <= 0 or length <= 0:
        raise GeometryError(f"geometry 'pipe': radius and length must be positive (got radius={radius:g}, length={length:g})")
    section = _SECTIONS[block]
    xy = transfinite(lambda p: section(p, radius), [points[:, 0], points[:, 1]])
    return np.column_stack([xy, length * points[:, 2]])
