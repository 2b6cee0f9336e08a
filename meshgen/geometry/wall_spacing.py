"""Wall spacing for body-fitted grids: the first-cell height that a target y+ asks for at a
Reynolds number, and the wall-normal node distances from that height out to the far field.

First cell: the flat-plate turbulent skin-friction estimate of Schlichting,
Cf = (2 log10(Re) - 0.65)^-2.3 (H. Schlichting, *Boundary-Layer Theory*, 7th ed., McGraw-Hill,
1979, ch. XXI, eq. 21.16; stated for Re < 1e9), at the Reynolds number of the reference length L;
the friction velocity u_tau = U sqrt(Cf / 2) gives h = y+ nu / u_tau = y+ L / (Re sqrt(Cf / 2)).

Wall-normal distances (``wall_normal_distances``): ``layers`` cells of height h at the wall, then
cells growing by one ratio q. Given a cap r on q, the count is the smallest for which growth at r
reaches the distance D; at that count q <= r is solved so that the cells sum to D exactly (every
ratio is q, none is capped separately). Given a count instead, q follows from it, and a count too
small to reach D under the cap is refused with the smallest count that works.

Across a wake cut (``cut_normal_distances``): the wall's distances with every cell raised so the
first is the cut's streamwise spacing over an aspect ratio high, scaled back to D, so the wake's cells stop
lengthening (in OpenFOAM's terms, growing in aspect ratio) downstream of the trailing edge.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from meshgen.errors import ParameterError
from meshgen.methods.clustering import Cluster, clustered_coordinates

__all__ = [
    "RE_RANGE",
    "YPLUS_RANGE",
    "cut_normal_distances",
    "FirstCell",
    "first_cell_height",
    "minimal_cell_count",
    "skin_friction",
    "spacing_summary",
    "wall_normal_distances",
]

RE_RANGE = (1e2, 1e10)  # Reynolds numbers accepted (per reference length)
YPLUS_RANGE = (0.0, 1000.0)  # y+ accepted: (low, high]


class FirstCell(NamedTuple):
    height: float  # first-cell height, in the units of the reference length
    cf: float  # the flat-plate skin-friction coefficient used


def _check_reynolds(reynolds: float) -> float:
    reynolds = float(reynolds)
    low, high = RE_RANGE
    if not (np.isfinite(reynolds) and low <= reynolds <= high):
        raise ParameterError("reynolds", f"{{name}} {reynolds:g} is outside [{low:g}, {high:g}]")
    return reynolds


def skin_friction(reynolds: float) -> float:
    """Schlichting's flat-plate turbulent skin friction Cf = (2 log10(Re) - 0.65)^-2.3 (see the
    module docstring); Re in ``RE_RANGE``."""
    reynolds = _check_reynolds(reynolds)
    return (2.0 * math.log10(reynolds) - 0.65) ** -2.3


def first_cell_height(y_plus: float, reynolds: float, length: float = 1.0) -> FirstCell:
    """The first-cell height h = y+ L / (Re sqrt(Cf/2)) (units of ``length``) that puts the first
    node off the wall at ``y_plus`` for a Reynolds number ``reynolds`` per reference length L,
    with Cf from ``skin_friction``. ParameterError for y+ outside (0, 1000], Re outside
    [1e2, 1e10] or L not positive."""
    y_plus = float(y_plus)
    low, high = YPLUS_RANGE
    if not (np.isfinite(y_plus) and low < y_plus <= high):
        raise ParameterError("y_plus", f"{{name}} {y_plus:g} is outside ({low:g}, {high:g}]")
    length = float(length)
    if not (np.isfinite(length) and length > 0):
        raise ParameterError("length", f"{{name}} {length:g}: the reference length must be positive")
    cf = skin_friction(reynolds)
    return FirstCell(y_plus * length / (float(reynolds) * math.sqrt(cf / 2.0)), cf)


def _check_distances(first: float, distance: float, ratio_cap: float, layers: int) -> tuple[float, float, float, int]:
    first, distance, ratio_cap = float(first), float(distance), float(ratio_cap)
    if not (np.isfinite(first) and first > 0):
        raise ParameterError("first", f"{{name}} {first:g}: the first-cell height must be positive")
    if not (np.isfinite(ratio_cap) and ratio_cap > 1.0):
        raise ParameterError("ratio_cap", f"{{name}} {ratio_cap:g}: the growth-ratio cap must be a number > 1")
    if int(layers) != layers or layers < 1:
        raise ParameterError("layers", f"{{name}} {layers}: the constant layers at the wall must be a whole number >= 1")
    layers = int(layers)
    if not (np.isfinite(distance) and distance > layers * first):
        raise ParameterError(
            "distance", f"{{name}} {distance:g}: must exceed the {layers} constant wall layers of height {first:g}"
        )
    return first, distance, ratio_cap, layers


def _reach(first: float, ratio: float, layers: int, cells: np.ndarray) -> np.ndarray:
    """Distance covered by ``cells`` cells: ``layers`` of height h, then h r, h r^2, ..."""
    grown = np.maximum(cells - layers, 0)
    return first * (np.minimum(cells, layers) + ratio * (ratio**grown - 1.0) / (ratio - 1.0))


def minimal_cell_count(first: float, distance: float, ratio_cap: float = 1.15, layers: int = 2) -> int:
    """The fewest cells that reach ``distance`` from a first height ``first`` with ``layers``
    constant cells and growth ratios at most ``ratio_cap``."""
    first, distance, ratio_cap, layers = _check_distances(first, distance, ratio_cap, layers)
    rest = distance - layers * first
    guess = layers + math.ceil(math.log1p(rest * (ratio_cap - 1.0) / (first * ratio_cap)) / math.log(ratio_cap))
    candidates = np.arange(max(layers + 1, guess - 2), guess + 3)
    return int(candidates[np.argmax(_reach(first, ratio_cap, layers, candidates) >= distance * (1 - 1e-14))])


def wall_normal_distances(
    first: float, distance: float, ratio_cap: float = 1.15, layers: int = 2, cells: int | None = None
) -> tuple[np.ndarray, float]:
    """Node distances from the wall, (m+1,) from 0 to ``distance`` D, and the growth ratio q used:
    ``layers`` cells of height ``first`` h, then cells growing by q (the module docstring gives
    the rule). ``cells`` None: m is the smallest count for which q <= ``ratio_cap``; else m =
    ``cells`` and q follows (ParameterError, naming the smallest count that works, when m is too
    few under the cap; and when m cells of height h already pass D)."""
    first, distance, ratio_cap, layers = _check_distances(first, distance, ratio_cap, layers)
    smallest = minimal_cell_count(first, distance, ratio_cap, layers)
    m = smallest if cells is None else int(cells)
    if cells is not None and (int(cells) != cells or m < smallest):
        raise ParameterError(
            "cells",
            f"{{name}} {cells}: too few to reach {distance:g} from a first cell of {first:g} with growth ratios "
            f"<= {ratio_cap:g}; the smallest count that works is {smallest}",
        )
    if m * first > distance * (1 + 1e-12):
        raise ParameterError(
            "cells", f"{{name}} {m}: {m} cells of height {first:g} pass {distance:g}; at most {int(distance // first)} fit"
        )
    # The growth part: the cells from the last constant one on, a geometric series from h.
    start = (layers - 1) * first
    span = distance - start
    grown = m - layers + 1
    if grown * first >= span * (1 - 1e-12):
        nodes = np.linspace(0.0, distance, m + 1)
        return nodes, 1.0
    tail = clustered_coordinates(grown, Cluster(axis=0, side="min", first_height=first / span))
    nodes = np.concatenate([np.arange(layers - 1) * first, start + span * tail])
    nodes[layers - 1 : layers + 1] = [start, start + first]  # the wall cells exactly h
    nodes[-1] = distance
    ratio = float((tail[2] - tail[1]) / (tail[1] - tail[0])) if grown > 1 else 1.0
    return nodes, ratio


def cut_normal_distances(distances, spacing, aspect: float) -> np.ndarray:
    """Node distances (n, m+1) from a wake cut along each of its n grid lines: the wall's
    ``distances`` (m+1,), from 0 to D, with every cell raised by max(0, ``spacing`` / ``aspect``
    minus the first cell), so the first is at least ``spacing / aspect`` high (``spacing`` (n,):
    the cut's streamwise cell length at each line, units of ``distances``; ``aspect`` > 0), then
    scaled by D over their sum so each line still ends at D. Raising cells by one amount lowers
    every growth ratio (none exceeds the wall's), and the lift fades smoothly outwards as the
    wall's cells grow past it (a cell's height, relative to its neighbour line's, changes slowly
    from row to row: a sharp switch from equal to the wall's cells put OpenFOAM's non-orthogonality
    at 65 degrees at 200:1 cells). A line whose ``spacing / aspect`` is at most the first cell
    keeps ``distances`` bit for bit."""
    d = np.asarray(distances, dtype=float)
    cells = np.diff(d)
    lift = np.maximum(np.asarray(spacing, dtype=float) / float(aspect) - cells[0], 0.0)
    out = np.zeros((len(lift), len(d)))
    np.cumsum(cells[None, :] + lift[:, None], axis=1, out=out[:, 1:])
    out *= d[-1] / out[:, -1:]
    out[:, -1] = d[-1]
    return np.where((lift > 0)[:, None], out, d[None, :])


def spacing_summary(nodes, ratio: float, layers: int = 2) -> str:
    """One line on wall-normal ``nodes`` (m+1,) and their growth ratio, e.g. ``108 cells to 100:
    first cell 4.46e-06, 2 constant layers, then growth ratio 1.1492``."""
    nodes = np.asarray(nodes, dtype=float)
    return (
        f"{len(nodes) - 1} cells to {nodes[-1]:.6g}: first cell {nodes[1] - nodes[0]:.3g}, "
        f"{layers} constant layer{'s' if layers != 1 else ''}, then growth ratio {ratio:.6g}"
    )
