"""The channel with a cylinder of the DFG benchmark (Schaefer and Turek, 1996), 2D, in twelve blocks
(meshgen.geometry.blocks): an O-grid of four blocks around the cylinder inside the square box
|x - 0.2|, |y - 0.2| <= BOX, and eight rectangles filling the channel around the box.

Channel [0, 2.2] x [0, 0.41], cylinder of diameter 0.1 centred at (0.2, 0.2). The O-grid's blocks
(``ring_e``, ``ring_n``, ``ring_w``, ``ring_s``) run from the cylinder (xi = 0) to a side of the
box (xi = 1), eta counterclockwise; the rectangles (``sw``, ``s``, ``se``, ``w``, ``e``, ``nw``,
``n``, ``ne``: compass points around the box) have xi along x and eta along y. Cells: N along each
side of the box (a quarter of the cylinder), M across the O-grid, graded so that its last cell
matches the box's cell size h = 2 BOX / N; the rectangles upstream, below and above the box have
cells of size about h, those downstream grow from h by the ratio 1 + wake_growth / N (parameter
``wake_growth``, default 1.5). For a given number of cells the forces on the cylinder are most
accurate with N large: the cells go to the cylinder and the box around it, and the far wake, where
the flow varies slowly, gets coarse cells (design notes §20).
"""

import numpy as np

from meshgen.errors import GeometryError

name = "dfg-cylinder"
dim = 2
description = "DFG benchmark channel 2.2 x 0.41 with a cylinder (D = 0.1 at (0.2, 0.2)): O-grid and 8 channel blocks"
params = {"wake_growth": 1.5}
dims_meaning = "N M: cells around a quarter of the cylinder (and along each side of the box around it), across the O-grid"
LENGTH, HEIGHT, CENTRE, RADIUS = 2.2, 0.41, (0.2, 0.2), 0.05
BOX = 0.1  # half-width of the O-grid's square box
RING = ("ring_e", "ring_n", "ring_w", "ring_s")
_X = (0.0, CENTRE[0] - BOX, CENTRE[0] + BOX, LENGTH)
_Y = (0.0, CENTRE[1] - BOX, CENTRE[1] + BOX, HEIGHT)
# Rectangle -> (column, row) in the 3 x 3 grid of x and y intervals (the box is (1, 1)).
RECTANGLES = {"sw": (0, 0), "s": (1, 0), "se": (2, 0), "w": (0, 1), "e": (2, 1), "nw": (0, 2), "n": (1, 2), "ne": (2, 2)}
blocks = RING + tuple(RECTANGLES)

interfaces = [(RING[k], "eta1", RING[(k + 1) % 4], "eta0") for k in range(4)] + [
    ("ring_e", "xi1", "e", "xi0"),
    ("ring_n", "xi1", "n", "eta0"),
    ("ring_w", "xi1", "w", "xi1"),
    ("ring_s", "xi1", "s", "eta1"),
    ("sw", "xi1", "s", "xi0"),
    ("s", "xi1", "se", "xi0"),
    ("nw", "xi1", "n", "xi0"),
    ("n", "xi1", "ne", "xi0"),
    ("sw", "eta1", "w", "eta0"),
    ("w", "eta1", "nw", "eta0"),
    ("se", "eta1", "e", "eta0"),
    ("e", "eta1", "ne", "eta0"),
]
_walls, _inlet, _outlet = ("walls", "wall"), ("inlet", "patch"), ("outlet", "patch")
block_patches = {
    **{ring: {"xi0": ("cylinder", "wall")} for ring in RING},
    "sw": {"xi0": _inlet, "eta0": _walls},
    "w": {"xi0": _inlet},
    "nw": {"xi0": _inlet, "eta1": _walls},
    "s": {"eta0": _walls},
    "n": {"eta1": _walls},
    "se": {"eta0": _walls, "xi1": _outlet},
    "e": {"xi1": _outlet},
    "ne": {"eta1": _walls, "xi1": _outlet},
}


def characteristic_length(**_params):
    return float(np.hypot(LENGTH, HEIGHT))


def geometric(cells: int, first: float, length: float) -> np.ndarray:
    """Parametric nodes (cells + 1 values from 0 to 1) growing geometrically from a first cell of
    ``first`` (physical) over ``length``: the ratio found by bisection (below 1 when even cells
    would be smaller than ``first``)."""
    target = first / length
    if abs(target * cells - 1.0) < 1e-12:
        return np.linspace(0.0, 1.0, cells + 1)
    low, high = 0.2, 5.0  # ratio bounds; the first cell's share falls as the ratio grows
    for _ in range(200):
        ratio = 0.5 * (low + high)
        share = (ratio - 1.0) / (ratio**cells - 1.0) if ratio != 1.0 else 1.0 / cells
        low, high = (ratio, high) if share > target else (low, ratio)
    steps = ratio ** np.arange(cells)
    return np.concatenate([[0.0], np.cumsum(steps) / steps.sum()])


def block_coords(dims, wake_growth=params["wake_growth"]):
    n, m = dims
    if n < 2 or m < 1:
        raise GeometryError(f"geometry '{name}': --dims needs N >= 2 and M >= 1, got {n} {m}")
    if not (np.isfinite(wake_growth) and 0.0 < wake_growth <= 10.0):
        raise GeometryError(f"geometry '{name}': wake_growth must be in (0, 10], got {wake_growth}")
    h = 2 * BOX / n
    box = np.linspace(0.0, 1.0, n + 1)
    # The O-grid: last cell of size h at the box's side (distance BOX - RADIUS): fine at the cylinder.
    ring = 1.0 - geometric(m, h, BOX - RADIUS)[::-1]
    # Cells downstream: growing by 1 + wake_growth / N from h over LENGTH - _X[2]. log1p keeps the
    # count right for a growth too close to 1 to show in 1 + g (g = 1e-300: even cells of size h).
    step = wake_growth / n
    downstream = int(np.ceil(np.log1p((LENGTH - _X[2]) * step / h) / np.log1p(step)))
    columns = [np.linspace(0.0, 1.0, max(1, round(_X[1] / h)) + 1), box, geometric(downstream, h, LENGTH - _X[2])]
    rows = [np.linspace(0.0, 1.0, max(1, round((_Y[i + 1] - _Y[i]) / h)) + 1) for i in range(3)]
    rows[1] = box
    return {**{r: [ring, box] for r in RING}, **{b: [columns[c], rows[r]] for b, (c, r) in RECTANGLES.items()}}


def _ring_east(points):
    """xi = 0 the cylinder's arc from -45 to 45 degrees, xi = 1 the box's side x = 0.2 + BOX."""
    xi, eta = points[:, 0], points[:, 1]
    angle = (eta - 0.5) * np.pi / 2
    inner = RADIUS * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    outer = np.stack([np.full_like(eta, BOX), BOX * (2.0 * eta - 1.0)], axis=1)
    return (1.0 - xi)[:, None] * inner + xi[:, None] * outer


def boundary(block, points, **_params):
    """(N, 2) points on the unit square's boundary -> (N, 2) points on block ``block``'s boundary."""
    if block in RECTANGLES:
        column, row = RECTANGLES[block]
        x = _X[column] + (_X[column + 1] - _X[column]) * points[:, 0]
        y = _Y[row] + (_Y[row + 1] - _Y[row]) * points[:, 1]
        return np.stack([x, y], axis=1)
    quarter = RING.index(block)
    cos, sin = np.cos(quarter * np.pi / 2), np.sin(quarter * np.pi / 2)
    return _ring_east(points) @ np.array([[cos, -sin], [sin, cos]]).T + np.asarray(CENTRE)
