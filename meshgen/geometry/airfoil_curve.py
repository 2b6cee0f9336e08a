"""An airfoil section as a curve: points, arc length, tangents and normals, the trailing edge, and
the chordwise distribution of mesh nodes along it.

A ``Section`` is a parametric curve p(t), t in [0, 1], running from the lower trailing-edge point
(t = 0) round the leading edge (t = ``le_parameter``) to the upper trailing-edge point (t = 1):
clockwise for a section with the upper surface above, so the outward normal is the tangent turned
by +90 degrees. Every public function takes arc length s in [0, ``length``] (units of the section's
coordinates, chord 1 for the built-in sections) measured from the lower trailing-edge point.

- Coordinate data (``spline_section``): p is a C2 cubic spline (scipy ``CubicSpline``, not-a-knot
  ends) through the points over their cumulative chord length, so the nodes at data parameters
  are the data points.
- Analytic sections (``analytic_section``): p is the exact formula, so every node s maps to a
  parameter t and the node is the formula evaluated at t (on the curve to rounding); only the
  arc-length map s(t) is numerical.

Arc length is 8-point Gauss-Legendre quadrature of |p'(t)| on each parameter interval (between
data points, or 512 equal steps of t for an analytic section); s -> t is inverted by Newton's
method on the same quadrature, to about 1e-13 of the length, from a first guess on the quadratic
through each interval's ends with its slower end's slope (exact to leading order where the speed
vanishes, as the sine parameter's does at the trailing edges: three steps suffice everywhere).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from meshgen.errors import GeometryError, ParameterError

__all__ = [
    "Section",
    "TrailingEdge",
    "analytic_section",
    "chord_length",
    "chordwise_distribution",
    "crest_arcs",
    "leading_edge_arc",
    "normals_at",
    "parameters_at",
    "points_at",
    "spline_section",
    "tangents_at",
    "trailing_edge",
    "vinokur",
]

_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(8)
ANALYTIC_INTERVALS = 512  # parameter intervals of an analytic section's arc-length table


@dataclass(frozen=True, eq=False)
class Section:
    """An airfoil section curve (see the module docstring). ``shape`` maps t (m,) to points (m, 2);
    ``derivative`` to dp/dt (m, 2); ``knots`` (k+1,) are the parameter breakpoints of the
    arc-length table ``knot_arcs`` (k+1,), ``knot_speeds`` (k+1,) |p'| there; ``points`` (n, 2) are the defining data points (or a
    sample of an analytic section), lower trailing edge -> leading edge -> upper trailing edge."""

    name: str
    shape: Callable[[np.ndarray], np.ndarray]
    derivative: Callable[[np.ndarray], np.ndarray]
    knots: np.ndarray
    knot_arcs: np.ndarray
    le_parameter: float
    points: np.ndarray
    analytic: bool
    knot_speeds: np.ndarray  # |p'(t)| at the knots (k+1,): the initial guess of parameters_at

    @property
    def length(self) -> float:
        """The arc length from the lower to the upper trailing-edge point."""
        return float(self.knot_arcs[-1])


def _arc_table(derivative, knots: np.ndarray) -> np.ndarray:
    """Cumulative arc length at ``knots``: Gauss-Legendre quadrature of |p'| per interval."""
    a, b = knots[:-1], knots[1:]
    t = 0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * _GAUSS_X[None, :]
    speed = np.linalg.norm(derivative(t.ravel()), axis=1).reshape(t.shape)
    pieces = 0.5 * (b - a) * (speed @ _GAUSS_W)
    return np.concatenate([[0.0], np.cumsum(pieces)])


def _speeds(derivative, knots: np.ndarray) -> np.ndarray:
    return np.linalg.norm(derivative(knots), axis=1)


def _partial_arcs(section: Section, interval: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Arc length from t = 0 to each t in its knot interval ``interval``."""
    a = section.knots[interval]
    nodes = 0.5 * (a + t)[:, None] + 0.5 * (t - a)[:, None] * _GAUSS_X[None, :]
    speed = np.linalg.norm(section.derivative(nodes.ravel()), axis=1).reshape(nodes.shape)
    return section.knot_arcs[interval] + 0.5 * (t - a) * (speed @ _GAUSS_W)


def analytic_section(name: str, shape, le_parameter: float, *, derivative=None, samples: int = 201, breaks=()) -> Section:
    """A section from an exact formula ``shape`` (t (m,) -> (m, 2), t in [0, 1], lower trailing
    edge to upper); ``derivative`` dp/dt, or the complex-step derivative Im p(t + ih) / h of
    ``shape`` (exact to rounding; ``shape`` must then accept complex t). ``breaks``: parameters
    where the formula's curvature jumps (a NACA camber line's junction), made knots of the
    arc-length table, whose quadrature then never straddles one (the arc lengths, and the nodes,
    move smoothly as a section parameter moves the junction)."""
    if derivative is None:

        def derivative(t, step=1e-30):
            return np.imag(shape(np.asarray(t, dtype=float) + 1j * step)) / step

    knots = np.unique(np.concatenate([np.linspace(0.0, 1.0, ANALYTIC_INTERVALS + 1), np.asarray(breaks, dtype=float)]))
    knots = knots[np.concatenate([[True], np.diff(knots) > 1e-9])]  # a break on a knot is that knot
    points = shape(np.linspace(0.0, 1.0, samples))
    arcs, speeds = _arc_table(derivative, knots), _speeds(derivative, knots)
    return Section(name, shape, derivative, knots, arcs, float(le_parameter), points, True, speeds)


def spline_section(name: str, points, le_index: int) -> Section:
    """A section through data ``points`` (n, 2), ordered lower trailing edge -> leading edge
    (``points[le_index]``) -> upper trailing edge: a C2 cubic spline over cumulative chord length
    (normalised to [0, 1]); the data are taken as checked (``meshgen.geometry.airfoils``)."""
    from scipy.interpolate import CubicSpline

    points = np.asarray(points, dtype=float)
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    if len(points) < 4 or not np.all(steps > 0):
        raise GeometryError(f"section '{name}': a spline needs at least 4 distinct consecutive points")
    knots = np.concatenate([[0.0], np.cumsum(steps)])
    knots /= knots[-1]
    knots[-1] = 1.0
    spline = CubicSpline(knots, points, axis=0)
    slope = spline.derivative()
    arcs, speeds = _arc_table(slope, knots), _speeds(slope, knots)
    return Section(name, spline, slope, knots, arcs, float(knots[le_index]), points, False, speeds)


def parameters_at(section: Section, s) -> np.ndarray:
    """The curve parameters t (m,) of arc lengths ``s`` (m,) in [0, length] (Newton's method)."""
    s = np.asarray(s, dtype=float).ravel()
    length = section.length
    if np.any(~np.isfinite(s)) or np.any(s < -1e-12 * length) or np.any(s > length * (1 + 1e-12)):
        raise ParameterError("s", f"{{name}}: arc lengths must lie in [0, {length:.6g}]")
    s = np.clip(s, 0.0, length)
    interval = np.clip(np.searchsorted(section.knot_arcs, s, side="right") - 1, 0, len(section.knots) - 2)
    a, b = section.knots[interval], section.knots[interval + 1]
    t = a + (b - a) * _first_guess(section, interval, s)
    for _ in range(30):
        error = _partial_arcs(section, interval, t) - s
        speed = np.linalg.norm(section.derivative(t), axis=1)
        step = error / np.maximum(speed, 1e-300)
        t = np.clip(t - step, a, b)
        if np.all(np.abs(error) <= 1e-14 * max(length, 1.0)):
            break
    return t


def _first_guess(section: Section, interval: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The fraction u (m,) of its knot interval where arc length ``s`` lies, on the quadratic s(u)
    through the interval's ends with the slope of its slower end: exact where the speed vanishes
    there (a trailing edge of the sine parameter, s ~ u^2), within O(h^3) elsewhere, so Newton's
    method starts close."""
    sa, sb = section.knot_arcs[interval], section.knot_arcs[interval + 1]
    h = section.knots[interval + 1] - section.knots[interval]
    va, vb = section.knot_speeds[interval] * h, section.knot_speeds[interval + 1] * h
    span = sb - sa
    start = va <= vb  # the model's slope is the slower end's
    slope, rise = np.where(start, va, vb), np.where(start, s - sa, sb - s)  # rise: from that end
    root = np.sqrt(np.maximum(slope * slope + 4.0 * (span - slope) * rise, 0.0))
    u = 2.0 * rise / np.where(slope + root > 0, slope + root, 1.0)
    return np.clip(np.where(start, u, 1.0 - u), 0.0, 1.0)


def points_at(section: Section, s) -> np.ndarray:
    """The points (m, 2) at arc lengths ``s`` (m,): on the exact formula for an analytic section."""
    return section.shape(parameters_at(section, s))


def tangents_at(section: Section, s) -> np.ndarray:
    """Unit tangents (m, 2) at arc lengths ``s``, pointing towards increasing s."""
    d = section.derivative(parameters_at(section, s))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def normals_at(section: Section, s) -> np.ndarray:
    """Unit outward normals (m, 2) at arc lengths ``s``: the tangent turned by +90 degrees (the
    section runs clockwise)."""
    tangent = tangents_at(section, s)
    return np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)


def leading_edge_arc(section: Section) -> float:
    """The arc length from the lower trailing-edge point to the leading edge."""
    interval = min(int(np.searchsorted(section.knots, section.le_parameter, side="right")) - 1, len(section.knots) - 2)
    return float(_partial_arcs(section, np.array([interval]), np.array([section.le_parameter]))[0])


def chord_length(section: Section) -> float:
    """The chord: the distance from the leading edge to the midpoint of the trailing-edge points."""
    le, lower, upper = section.shape(np.array([section.le_parameter, 0.0, 1.0]))
    return float(np.linalg.norm(0.5 * (lower + upper) - le))


class TrailingEdge(NamedTuple):
    sharp: bool  # the gap is below the tolerance
    gap: float  # the distance between the two trailing-edge points, as a fraction of chord
    lower: np.ndarray  # (2,) the lower trailing-edge point (s = 0)
    upper: np.ndarray  # (2,) the upper trailing-edge point (s = length)


def trailing_edge(section: Section, tol: float = 1e-5) -> TrailingEdge:
    """Whether the trailing edge is sharp (gap below ``tol`` of chord) or blunt; for a blunt one,
    the base is the straight segment from ``lower`` to ``upper``."""
    lower, upper = section.shape(np.array([0.0, 1.0]))
    gap = float(np.linalg.norm(upper - lower)) / chord_length(section)
    return TrailingEdge(gap < tol, gap, lower, upper)


def _stretch(n: int, first: float, last: float) -> np.ndarray:
    """Vinokur's two-sided stretching (J. Comput. Phys. 50, 1983): n+1 values on [0, 1] with
    derivative-matched end spacings ``first`` and ``last`` (fractions of the length)."""
    from scipy.optimize import brentq

    xi = np.arange(n + 1) / n
    a = np.sqrt(last / first)
    b = 1.0 / (n * np.sqrt(first * last))
    if b > 1.001:
        d = brentq(lambda x: np.log(np.sinh(x) / x) - np.log(b), 1e-6, 700.0, xtol=1e-15)
        u = 0.5 * (1.0 + np.tanh(d * (xi - 0.5)) / np.tanh(0.5 * d))
    elif b < 0.999:
        d = brentq(lambda x: np.sin(x) / x - b, 1e-9, np.pi - 1e-12, xtol=1e-15)
        u = 0.5 * (1.0 + np.tan(d * (xi - 0.5)) / np.tan(0.5 * d))
    else:
        u = xi * (1.0 + 2.0 * (b - 1.0) * (xi - 0.5) * (1.0 - xi))
    s = u / (a + (1.0 - a) * u)
    s[0], s[-1] = 0.0, 1.0
    return s


def vinokur(n: int, first: float, last: float) -> np.ndarray:
    """(n+1,) increasing values from 0 to 1 whose first and last steps are ``first`` and ``last``
    (fractions of the length, met to 1e-10): Vinokur's two-sided stretching, its end spacings
    corrected by fixed-point iteration (the formula matches derivatives, not cells).
    ParameterError when n < 2 or the two spacings do not fit in n cells."""
    n = int(n)
    if n < 2:
        raise ParameterError("cells", f"{{name}} {n}: two-sided clustering needs at least 2 cells")
    if not (0 < first and 0 < last and first + last < 1):
        raise ParameterError("spacing", f"{{name}}: end spacings {first:.3g} and {last:.3g} of the length do not fit in it")
    wanted_first, wanted_last = first, last
    for _ in range(100):
        s = _stretch(n, first, last)
        got_first, got_last = s[1], 1.0 - s[-2]
        if abs(got_first / wanted_first - 1) < 1e-11 and abs(got_last / wanted_last - 1) < 1e-11:
            return s
        first *= wanted_first / got_first
        last *= wanted_last / got_last
    raise ParameterError(
        "spacing",
        f"{{name}}: end spacings {wanted_first:.3g} and {wanted_last:.3g} of the length cannot both be met with {n} cells",
    )


def chordwise_distribution(
    section: Section, cells: int, le_spacing: float, te_spacing: float, crest: tuple | None = None
) -> np.ndarray:
    """Arc lengths (cells+1,) of the nodes round the section, lower trailing edge -> leading edge
    -> upper trailing edge, with the leading edge a node: ``cells`` split between the surfaces in
    proportion to their arc lengths, each surface clustered by ``vinokur`` so that its cells at the
    leading and trailing edges are ``le_spacing`` and ``te_spacing`` of chord long (arc length).
    ``crest`` (spacing, up): each surface's crest (``crest_arcs``: its point farthest along the unit
    vector ``up`` (2,), the lower surface's least far) a node too, where it is not an edge (the
    nearest node moved onto it, its neighbours part of the way), and its cells at most ``spacing``
    chords long (a number, or a pair: the lower surface's, the upper's; ``_surface``). A blunt
    trailing edge's base is not included."""
    cells = int(cells)
    if cells < 4:
        raise ParameterError("cells", f"{{name}} {cells}: a section needs at least 4 cells round it")
    for name, value in (("le_spacing", le_spacing), ("te_spacing", te_spacing)):
        if not (np.isfinite(value) and 0 < value < 0.5):
            raise ParameterError(name, f"{{name}} {value:g}: the spacing must be a fraction of chord in (0, 0.5)")
    chord, length, s_le = chord_length(section), section.length, leading_edge_arc(section)
    lower_cells = min(max(int(round(cells * s_le / length)), 2), cells - 2)
    ends = ((0.0, s_le, lower_cells, te_spacing * chord, le_spacing * chord),
            (s_le, length, cells - lower_cells, le_spacing * chord, te_spacing * chord))  # fmt: skip
    arcs, caps = (None, None), (None, None)
    if crest is not None:
        arcs, caps = crest_arcs(section, crest[1]), np.broadcast_to(np.asarray(crest[0], dtype=float) * chord, (2,))
    surfaces = [_surface(*end, at, cap) for end, at, cap in zip(ends, arcs, caps)]
    nodes = np.concatenate([surfaces[0], surfaces[1][1:]])
    nodes[0], nodes[lower_cells], nodes[-1] = 0.0, s_le, length
    return nodes


def crest_arcs(section: Section, up) -> tuple:
    """The arc lengths of the lower surface's point least far along the unit vector ``up`` (2,)
    and of the upper surface's farthest (where the tangent is square to ``up``, to rounding: a
    smooth function of the section, for the derivatives of a family's meshes), each None where
    that point is an end of the surface (the leading or the trailing edge)."""
    from scipy.optimize import brentq

    up = np.asarray(up, dtype=float)
    s_le, length = leading_edge_arc(section), section.length
    out = []
    for start, end, sign in ((0.0, s_le, -1.0), (s_le, length, 1.0)):
        s = np.linspace(start, end, 2001)
        k = int(np.argmax(sign * points_at(section, s) @ up))
        if k < 2 or k > len(s) - 3:
            out.append(None)
            continue
        rate = lambda x: float(tangents_at(section, np.array([x]))[0] @ up)  # noqa: E731 (d height / d s)
        low, high = s[k - 1], s[k + 1]
        out.append(
            float(brentq(rate, low, high, xtol=1e-15, rtol=4 * np.finfo(float).eps)) if rate(low) * rate(high) < 0 else None
        )
    return tuple(out)


CREST_REACH = 8  # nodes each side of a crest's node that move with it (the rest of the surface stays)


def _surface(start: float, end: float, n: int, first: float, last: float, crest: float | None, spacing: float | None):
    """Arc lengths (n+1,) from ``start`` to ``end``: Vinokur with end cells ``first``, ``last``; with
    a ``crest`` arc, the node nearest it moved onto it and its ``CREST_REACH`` neighbours each side
    part of the way, in the nodes' index (the distribution, monotone-interpolated between its nodes,
    sampled at k + f cos^2(...) with f the crest's fractional index offset, at most a half: each
    node moves by less than its cells, the others stay bit for bit); where the crest's cell
    (interpolated between cell centres) is longer than ``spacing``, two Vinokur segments joined at
    a node on the crest instead, its cells ``spacing`` long (the nearest node's count of cells each
    side; one segment still where the crest is too near an end for them)."""
    from scipy.interpolate import PchipInterpolator
    from scipy.optimize import brentq

    span = end - start
    nodes = start + span * vinokur(n, first / span, last / span)
    if crest is None:
        return nodes
    j = int(np.clip(np.argmin(np.abs(nodes - crest)), 2, n - 2))
    if not nodes[j - 1] < crest < nodes[j + 1]:  # next to an edge's cell
        return nodes
    if np.interp(crest, 0.5 * (nodes[1:] + nodes[:-1]), np.diff(nodes)) <= spacing:
        at = PchipInterpolator(np.arange(n + 1.0), nodes)  # monotone in the index
        offset = brentq(lambda x: float(at(x)) - crest, j - 1.0, j + 1.0, xtol=1e-13) - j
        k = np.arange(max(j - CREST_REACH, 1), min(j + CREST_REACH, n - 1) + 1)
        nodes[k] = at(k + offset * np.cos(0.5 * np.pi * (k - j) / (CREST_REACH + 1)) ** 2)
        nodes[j] = crest
        return nodes
    try:
        before = start + (crest - start) * vinokur(j, first / (crest - start), spacing / (crest - start))
        after = crest + (end - crest) * vinokur(n - j, spacing / (end - crest), last / (end - crest))
    except ParameterError:  # a crest too near an edge for its cells: the surface stays one segment
        return nodes
    return np.concatenate([before, after[1:]])
