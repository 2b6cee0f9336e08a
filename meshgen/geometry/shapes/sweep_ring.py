"""A swept solid's cap whose loop mixes sharp corners and smooth joints (a box with a filleted
edge: a rectangle with a rounded corner) cut into a ring of two blocks per curve around a core
(``sweep_blocks``).

The centroid construction (``ring_blocks``) is kept where it is good (a square cap); else the
core is the loop offset inwards: each curve's end (a CAD vertex) is joined by a straight
spoke to a core corner along the bisector of the loop's two inward normals there (a sharp
corner's bisector, a smooth joint's normal), at the depth that puts the corner ``1 - RING`` of
the way from the loop to the centroid's nearest boundary point away from both of the loop's
sides (a 90 degree corner's spoke is sqrt(2) times as long). Each spoke ends at most ``SPOKE``
of the way to where it meets a neighbouring spoke: the two normals at a fillet's ends meet at its
centre, a radius from the loop, which a depth set by the cap's size crosses on an elongated cap
or a large fillet (the blocks on the arc fold). Depths set from the nearest boundary point, not
from the centroid's distance to each vertex, keep an elongated cap's ring as thick along its
long sides as along its short ones, and the spokes at its corners at 45 degrees to its sides.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "PLAIN",
    "RING",
    "SEARCHES",
    "SHARES",
    "SIMPLEX",
    "SPOKE",
    "coons",
    "piece",
    "ring_blocks",
    "ring_corners",
    "segment",
    "worst_corner",
]

RING = 0.6  # the centroid construction's core corners: this share of the way to the loop's (the offset: 1 - of a depth)
SPOKE = 0.6  # and a spoke runs at most this share of the way to where it meets a neighbouring one
SHARES = (0.15, 0.85)  # a core side meets its curve's midpoint spoke within these shares of it
PLAIN = 0.6  # the centroid construction is kept where no cell corner of its cap map is sharper (sine)
SEARCHES = 2  # Nelder-Mead searches of the offset core, each from the last one's best
SIMPLEX = 0.1  # their first simplex's steps: the meeting point in the cap's size, the shares
_STEP = 1e-4  # a curve's tangent at its ends: the chord over this share of it


def coons(sides, xi: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """(N, 2) the Coons patch of ``sides`` (left xi=0 and right xi=1 along eta, bottom eta=0 and
    top eta=1 along xi; callables t (N,) -> (N, 2)) at (xi, eta)."""
    left, right, bottom, top = sides
    b0, b1, t0, t1 = bottom(np.zeros(1))[0], bottom(np.ones(1))[0], top(np.zeros(1))[0], top(np.ones(1))[0]
    x, e = xi[:, None], eta[:, None]
    return (
        (1 - x) * left(eta) + x * right(eta) + (1 - e) * bottom(xi) + e * top(xi)
        - ((1 - x) * (1 - e) * b0 + x * (1 - e) * b1 + (1 - x) * e * t0 + x * e * t1)
    )  # fmt: skip


def worst_corner(blocks, cells: int = 8) -> float:
    """The smallest sine of a cell corner's angle (a quadrilateral's scaled Jacobian; negative
    where a block folds) over ``cells`` x ``cells`` cells of each block's Coons map."""
    t = np.linspace(0.0, 1.0, cells + 1)
    xi, eta = (a.ravel() for a in np.meshgrid(t, t, indexing="ij"))
    worst = np.inf
    for sides in blocks.values():
        p = coons(sides, xi, eta).reshape(cells + 1, cells + 1, 2)
        ring = [p[:-1, :-1], p[1:, :-1], p[1:, 1:], p[:-1, 1:]]  # each cell's corners counterclockwise
        for k in range(4):
            e1, e2 = ring[(k + 1) % 4] - ring[k], ring[k - 1] - ring[k]
            cross = e1[..., 0] * e2[..., 1] - e1[..., 1] * e2[..., 0]
            worst = min(worst, float((cross / (np.linalg.norm(e1, axis=-1) * np.linalg.norm(e2, axis=-1))).min()))
    return worst


def segment(a: np.ndarray, b: np.ndarray):
    """The straight side from point ``a`` to ``b`` (2,) as a curve t (N,) -> (N, 2)."""
    return lambda t: a + np.asarray(t, dtype=float)[:, None] * (b - a)


def piece(curve, start: float, stop: float):
    """The part of ``curve`` from parameter ``start`` to ``stop``, parametrised on [0, 1]."""
    return lambda t: curve(start + np.asarray(t, dtype=float) * (stop - start))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _left(v: np.ndarray) -> np.ndarray:
    """(N, 2) ``v`` turned counterclockwise by 90 degrees: inwards for a counterclockwise loop."""
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)


def ring_corners(curves) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The loop's vertices (n, 2) (curve k starts at vertex k; the centroid is the origin), the
    spokes' unit directions (n, 2) (the bisector of the inward normals of curves k - 1 and k at
    vertex k) and the core's corners (n, 2) (module docstring)."""
    n = len(curves)
    vertex = np.array([curve(np.zeros(1))[0] for curve in curves])
    leaving = _unit(np.array([curve(np.array([_STEP]))[0] for curve in curves]) - vertex)
    arriving = _unit(vertex - np.array([curves[k - 1](np.array([1.0 - _STEP]))[0] for k in range(n)]))
    inward = _left(leaving)
    direction = _unit(inward + _left(arriving))
    dense = np.concatenate([curve(np.linspace(0.0, 1.0, 257)) for curve in curves])
    depth = (1.0 - RING) * float(np.linalg.norm(dense, axis=1).min())
    length = depth / np.maximum(np.einsum("ij,ij->i", direction, inward), 0.2)  # depth from both sides
    for k in range(n):  # where spokes k and k + 1 meet: vertex[k] + s d[k] = vertex[k + 1] + u d[k + 1]
        after = (k + 1) % n
        matrix = np.stack([direction[k], -direction[after]], axis=1)
        if abs(np.linalg.det(matrix)) < 1e-9:
            continue  # parallel spokes never meet
        s, u = np.linalg.solve(matrix, vertex[after] - vertex[k])
        if s > 0.0 and u > 0.0:
            length[k], length[after] = min(length[k], SPOKE * s), min(length[after], SPOKE * u)
    return vertex, direction, vertex + length[:, None] * direction


def _assemble(halves, vertex, inner, middle, centre, shares):
    """The ring's and the core's blocks: the side inner[k] -> inner[k + 1] meets the spoke to
    curve k's midpoint ``shares[k]`` of the way along; the core's quadrilaterals meet at ``centre``."""
    n = len(halves)
    joint = [inner[k] + shares[k] * (inner[(k + 1) % n] - inner[k]) for k in range(n)]
    blocks = {}
    for k in range(n):
        after = (k + 1) % n
        blocks[f"a{k}"] = (
            segment(inner[k], joint[k]),
            halves[k][0],
            segment(inner[k], vertex[k]),
            segment(joint[k], middle[k]),
        )
        blocks[f"b{k}"] = (
            segment(joint[k], inner[after]),
            halves[k][1],
            segment(joint[k], middle[k]),
            segment(inner[after], vertex[after]),
        )
        blocks[f"quad{k}"] = (
            segment(centre, joint[k]),
            segment(joint[k - 1], inner[k]),
            segment(centre, joint[k - 1]),
            segment(joint[k], inner[k]),
        )
    return blocks


def ring_blocks(curves, faces, sharp):
    """A ring of two blocks per curve (``a<k>``, ``b<k>``: its halves; xi from the core outwards)
    around a core polygon cut into ``quad<k>`` meeting at one point, so every block corner on the
    loop is a CAD vertex or a curve's midpoint. First the centroid construction (corners ``RING``
    of the way from the centroid to the loop's sharp corners, as deep along the normal at smooth
    joints, the quadrilaterals meeting at the centroid), kept where its worst cell corner's sine
    is at least ``PLAIN`` (a square cap: the elliptic method smooths it better); else the offset
    core (``ring_corners``) whose meeting point (first the centroid) and the points where the
    spokes to the curves' midpoints meet its sides (first where the curves' normals cross them)
    are moved to maximise ``worst_corner`` (Nelder-Mead): on an elongated cap the quadrilaterals
    at its ends are otherwise slivers (sides 18 degrees apart at the centroid of a 3 x 1 cap).
    (blocks, sides on CAD faces, interfaces, whether the core is the offset one)."""
    from scipy.optimize import minimize

    n = len(curves)
    vertex, _, inner = ring_corners(curves)
    middle = np.array([curve(np.array([0.5]))[0] for curve in curves])
    halves = [(piece(curve, 0.0, 0.5), piece(curve, 0.5, 1.0)) for curve in curves]
    plain = _assemble(halves, vertex, _centroid_corners(curves, vertex, sharp), middle, np.zeros(2), np.full(n, 0.5))
    if worst_corner(plain) >= PLAIN:
        return plain, *_patches(faces), False
    normal = _left(_unit(np.array([curve(np.array([0.5 + _STEP]))[0] for curve in curves]) - middle))
    shares = np.full(n, 0.5)
    for k in range(n):  # where the normal at curve k's midpoint crosses the side inner[k] -> inner[k + 1]
        matrix = np.stack([inner[(k + 1) % n] - inner[k], -normal[k]], axis=1)
        if abs(np.linalg.det(matrix)) > 1e-12:
            shares[k] = np.clip(np.linalg.solve(matrix, middle[k] - inner[k])[0], *SHARES)
    scale = float(np.linalg.norm(vertex, axis=1).max())

    def blocks_of(x):
        return _assemble(halves, vertex, inner, middle, scale * x[:2], np.clip(x[2:], *SHARES))

    start = np.concatenate([np.zeros(2), shares])
    x, value = start, -worst_corner(blocks_of(start), 4)
    for _ in range(SEARCHES):  # each search from the last one's best, with a fresh simplex of SIMPLEX steps
        simplex = np.vstack([x, x + SIMPLEX * np.eye(len(x))])
        options = {"maxfev": 60 * (n + 2), "xatol": 1e-3, "fatol": 1e-4, "initial_simplex": simplex}
        found = minimize(lambda y: -worst_corner(blocks_of(y), 4), x, method="Nelder-Mead", options=options)
        if found.fun < value:
            x, value = found.x, float(found.fun)
    blocks = blocks_of(x)
    return blocks, *_patches(faces), True


def _centroid_corners(curves, vertex, sharp):
    """(n, 2) the core's corners ``RING`` of the way from the centroid to each sharp corner, and at
    a smooth joint as deep along the normal (the first construction: on a square cap)."""
    inner = []
    for k, curve in enumerate(curves):
        if sharp[k]:
            inner.append(RING * vertex[k])
        else:
            tangent = curve(np.array([1e-3]))[0] - vertex[k]
            normal = np.array([-tangent[1], tangent[0]]) / np.linalg.norm(tangent)
            inner.append(vertex[k] + (1.0 - RING) * np.linalg.norm(vertex[k]) * normal)
    return np.array(inner)


def _patches(faces):
    """The ring blocks' sides on CAD faces and the blocks' interfaces."""
    n = len(faces)
    patches, interfaces = {}, []
    for k in range(n):
        after = (k + 1) % n
        patches[f"a{k}"] = {"xi1": faces[k]}
        patches[f"b{k}"] = {"xi1": faces[k]}
        interfaces += [
            (f"a{k}", "eta1", f"b{k}", "eta0"),
            (f"b{k}", "eta1", f"a{after}", "eta0"),
            (f"quad{k}", "xi1", f"b{(k - 1) % n}", "xi0"),
            (f"quad{k}", "eta1", f"a{k}", "xi0"),
            (f"quad{k}", "eta0", f"quad{(k - 1) % n}", "xi0"),
        ]
    return patches, interfaces
