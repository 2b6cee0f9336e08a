"""An airfoil section in a 2D far field, meshed to the wall (y+ about 1): a C-grid when the trailing
edge is sharp, an O-grid when it is blunt (meshgen.geometry.blocks, three blocks either way).

Section (``meshgen.geometry.airfoils``): NACA 4- or 5-digit ``naca`` (a number: 12 is NACA 0012,
2412, 23012), or, with ``thickness`` T > 0, the 4-digit section of continuous parameters (camber
``camber`` at ``camber_position``, thickness T, chords; closed trailing edge: a C-grid; what a
family of sections varies, ``meshgen.neural.wall_family``), chord 1, turned by ``alpha`` degrees (nose up) about the quarter chord with its whole
grid (the wake cut leaves along the chord line, the outflow square to it); ``sharp=1``
closes its trailing edge (NACA 0012: the NASA TMR formula, whose wall nodes lie on it to
rounding; others: a4 = -0.1036). Or a Selig or Lednicer coordinate file named as the geometry
(``-g naca2414.dat``: ``file_module``): its C2 spline is the wall (the wall nodes lie on it), the
file's trailing edge decides C- or O-grid, and ``naca``, ``sharp`` are not parameters.

Blocks ``lower``, ``section``, ``upper`` in a row along the wall (xi along it, eta from the wall
outwards; (xi, eta) right-handed). C-grid: ``lower`` lies under the wake cut (xi from the outflow
to the trailing edge), ``section`` round the section (lower trailing edge, leading edge, upper
trailing edge), ``upper`` above the cut; the cut is the interface lower.eta0 = upper.eta0, the
outflow the patch ``outlet``. O-grid: the closed wall from the middle of the blunt base, split at
the middle of the lower and of the upper surface. Patches ``wall`` (eta0 on the section) and
``farfield`` (every eta1).

The boundary map of each block is x(xi, eta) = w(xi) + eta D e(xi): w the wall (or the cut) at
arc fraction xi, D = ``farfield`` chords, e a unit direction (the cut's: straight down or up;
the section's, C-grid: turning from down at the lower trailing edge through upstream at the
leading edge to up, at half the rate of the polar angle about the mid-chord point of the mean
line, or the mean line's point nearest it about which the section is star-shaped (a thin, strongly
cambered section); O-grid: radial from it). TFI reproduces it, so the TFI mesh's straight grid lines have their first cells exactly of
the asked height; the parametric eta nodes are the wall-normal distances over D, the nodes'
spacing is ``meshgen.geometry.airfoil_spacing``'s. ``mesh_elliptic`` (the hook of ``meshgen.run.meshing``)
marches every layer off the wall (``meshgen.methods.hyperbolic``) and blends the layers beyond one
chord into the TFI mesh: no Winslow equations are solved (a Winslow outer region keeps harmonic, not
the designed, wall-normal spacing: see ``mesh_elliptic``); the wake cut's lines take their own
distances, their first cells growing downstream with the cut's (``airfoil_spacing.line_distances``;
not the TFI mesh's: its eta nodes are one set for every line).

A third --dims number K extrudes the set into a straight wing section (``extruded``): every block
times [0, ``span``] along z, K equal cells, the 2D patches plus ``front`` (z = 0) and ``back``
(z = span), symmetry planes; the cut stays an interface; the mesh is the 2D mesh extruded.

Grid families: ``level`` K scales the cells per direction by 1.5^K (DPW) and every designed length
(first cell, leading- and trailing-edge spacing) by (2/3)^K, so the family's grids are similar
(the y+ of the first cell falls with them).
"""

import dataclasses
import functools
import math
import time

import numpy as np

from meshgen.errors import GeometryError, ParameterError
from meshgen.geometry import airfoil_spacing
from meshgen.geometry.airfoil_spacing import first_height, level_scale
from meshgen.methods.clustering import respaced_lines, smoothed_spacing

name = "airfoil"
dim = 2
description = "NACA airfoil section in a far field, to the wall (y+ 1): C-grid (sharp trailing edge) or O-grid (blunt)"
params = {
    "naca": 12.0,
    "sharp": 0.0,
    "thickness": 0.0,
    "camber": 0.0,
    "camber_position": 0.4,
    "farfield": 100.0,
    "wake": 0.0,
    "alpha": 0.0,
    "yplus": 1.0,
    "reynolds": 6e6,
    "first_height": 0.0,
    "growth": 1.15,
    "layers": 2.0,
    "le_spacing": 0.002,
    "te_spacing": 0.001,
    "level": 0.0,
}
dims_meaning = (
    "N M [K]: cells along the wall (C-grid: round the section and along both sides of the wake cut, a fifth "
    "of them on each side of the cut at least; O-grid: round the section and across its blunt base), "
    "cells from the wall to the far field; --param level=K makes them round(1.5^K N), round(1.5^K M); "
    "a third number K: a straight wing section, K equal cells along the span (z, --param span=S chords, "
    "default 1; side planes front and back, symmetry)"
)
shown_dims = (448, 128)  # what `meshgen geometries show` builds the set with (4 cells cannot reach the far field)
blocks = ("lower", "section", "upper")
# What a member of a family of sections (meshgen.neural.wall_family) sets at will: the wall spacing,
# which the network's frame applies exactly; the section and the far field are the family's.
wall_free = ("yplus", "reynolds", "first_height", "growth", "layers", "le_spacing", "te_spacing", "level")
train_dims = (448, 128)  # meshgen train: the marched mesh the wall-layer network learns (TMR's 449 x 129 points)
MARCH_SMOOTHING = (0.05, 0.1, 0.2, 0.4)  # the march's dissipation, tried in turn (a thick section with aft camber folds at 0.05)
BLEND_START = 1.0  # chords: the marched layers beyond this distance are blended into straight lines
FARFIELD_SMOOTHING = 8.0  # cells over which the far field's spacing is smoothed


SECTION_PARAMS = ("naca", "sharp", "thickness", "camber", "camber_position")  # the section's (a file's replaces them)
_SECTION_DEFAULTS = {k: params[k] for k in SECTION_PARAMS}  # what a file's copy, without them, checks
SECTION_FILE = None  # the coordinate file of a copy made by ``file_module``; None: the NACA section
FILE_SECTION = None  # its spline Section


def file_module(path):
    """A copy of this plugin whose section is the Selig or Lednicer file ``path`` (read and checked
    now: GeometryError on one line for a bad file), without the ``naca`` and ``sharp`` parameters."""
    import importlib.util
    import sys

    from meshgen.geometry.airfoils import read_section

    section = read_section(path)
    spec = importlib.util.spec_from_file_location(f"{__name__}_file_{abs(hash(str(path))):x}", __file__)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    module.SECTION_FILE, module.FILE_SECTION = str(path), section
    module.params = {k: v for k, v in params.items() if k not in SECTION_PARAMS}
    module.description = f"airfoil section of {path} ({section.name}) in a far field, to the wall (y+ 1)"
    return module


@functools.lru_cache(maxsize=1)
def extruded():
    """The 3D straight wing section (``--dims N M K``): this block set swept ``span`` chords along z
    (``meshgen.geometry.extrusion.extruded_plugin``: side planes ``front``, ``back``, symmetry)."""
    import sys

    from meshgen.geometry.extrusion import extruded_plugin

    sides = (("front", "symmetry"), ("back", "symmetry"))
    return extruded_plugin(sys.modules[__name__], "span", 1.0, sides, filled=True)  # w + eta D e fills the square


def _sharp_te(values) -> bool:
    return _setup(_key(values)).sharp


def interfaces(**values):
    """The cut (C-grid) or the base's middle (O-grid) closes the row of blocks."""
    ring = [("lower", "xi1", "section", "xi0"), ("section", "xi1", "upper", "xi0")]
    return ring + ([("lower", "eta0", "upper", "eta0")] if _sharp_te(values) else [("upper", "xi1", "lower", "xi0")])


def check_family_member(values, varied) -> None:
    """A member of a family of sections (``meshgen.neural.wall_family``) varying ``varied`` (names):
    a varied thickness must stay above 0 (thickness 0 selects the ``naca`` section, another shape)."""
    if "thickness" in varied and float(values["thickness"]) <= 0:
        raise GeometryError(f"thickness {float(values['thickness']):g} is no section: a varied thickness must stay above 0")


def wall_layout(values):
    """The row of blocks round the wall for ``meshgen.neural.wall_map``: node eta at distance eta D
    from the wall (or the cut); a ring of blocks (O-grid) or an open row (C-grid)."""
    v = {**params, **values}
    setup = _setup(_key(v))
    # Below d0 the grid lines are the wall normals: about the trailing-edge spacing for a C-grid (beyond it
    # the march has turned the lines at the concave trailing edge apart), several base widths for an
    # O-grid (the normals of the base's convex corners part: the march fans them out beyond).
    blend = v["te_spacing"] * level_scale(v) if setup.sharp else max(4.0 * setup.gap, v["te_spacing"] * level_scale(v))
    return {"distance": float(v["farfield"]), "closed": not setup.sharp, "blend_distance": float(blend)}


def block_patches(**values):
    far = {"eta1": ("farfield", "patch")}
    if _sharp_te(values):
        outlet = ("outlet", "patch")
        return {"lower": {**far, "xi0": outlet}, "section": {**far, "eta0": ("wall", "wall")}, "upper": {**far, "xi1": outlet}}
    return {block: {**far, "eta0": ("wall", "wall")} for block in blocks}


def characteristic_length(**values):
    return 2.0 * float(values["farfield"]) + 1.0


# ---------------------------------------------------------------------------------------------
# the section, the cut and their directions


def _key(values) -> tuple:
    return tuple(float(values.get(k, v)) for k, v in params.items())


def _values(key: tuple) -> dict:
    return {**_SECTION_DEFAULTS, **dict(zip(params, key))}


def _check(v: dict) -> None:
    if not (2.0 <= v["farfield"] <= 1e4):
        raise ParameterError("farfield", f"{{name}} {v['farfield']:g}: the far field must lie 2 to 10000 chords from the wall")
    if not (v["wake"] == 0 or 1.0 <= v["wake"] <= 1e4):
        raise ParameterError("wake", f"{{name}} {v['wake']:g}: the wake cut must be 1 to 10000 chords long (0: the far field's)")
    if not (1.0 < v["growth"] <= 2.0):
        raise ParameterError("growth", f"{{name}} {v['growth']:g}: the growth-ratio cap must be above 1 (and at most 2)")
    if v["layers"] != int(v["layers"]) or not 1 <= v["layers"] <= 50:
        raise ParameterError("layers", f"{{name}} {v['layers']:g}: the constant wall layers must be a whole number 1 to 50")
    if not abs(v["alpha"]) <= 30:
        raise ParameterError("alpha", f"{{name}} {v['alpha']:g}: the incidence must lie within +-30 degrees")
    if v["thickness"] == 0 and (v["camber"] != 0 or v["camber_position"] != _SECTION_DEFAULTS["camber_position"]):
        raise ParameterError("camber", "{name}: camber and camber_position shape a section of --param thickness=T (T > 0)")
    if v["sharp"] not in (0.0, 1.0):
        raise ParameterError("sharp", f"{{name}} {v['sharp']:g}: 0 (the section's own trailing edge) or 1 (closed)")
    for key in ("le_spacing", "te_spacing"):
        if not (0 < v[key] <= 0.05):
            raise ParameterError(key, f"{{name}} {v[key]:g}: the spacing must be a fraction of chord in (0, 0.05]")
    if v["level"] != int(v["level"]) or not -3 <= v["level"] <= 4:
        raise ParameterError("level", f"{{name}} {v['level']:g}: the grid level must be a whole number -3 to 4")
    if v["first_height"] != 0 and not (0 < v["first_height"] <= 0.01):
        raise ParameterError(
            "first_height", f"{{name}} {v['first_height']:g}: the first cell must be 0 (from yplus and Re) or in (0, 0.01] chord"
        )


def _designation(v: dict) -> str:
    naca = v["naca"]
    if naca != int(naca) or not 1 <= naca <= 99999:
        raise GeometryError(f"geometry 'airfoil': naca={naca:g} is not a NACA 4- or 5-digit designation (e.g. 12, 2412, 23012)")
    digits = f"{int(naca):04d}"
    return "tmr0012" if v["sharp"] and digits == "0012" else digits


@dataclasses.dataclass(frozen=True)
class _Setup:
    section: object  # meshgen.geometry.airfoil_curve.Section (unturned)
    sharp: bool
    turn: np.ndarray  # (2, 2) rotation by -alpha
    pivot: np.ndarray  # (2,) the quarter chord
    te: np.ndarray  # (2,) the trailing edge (the base's middle when blunt), before the turn by alpha
    centre: np.ndarray  # (2,) the point the directions turn about: the mean line's at mid-chord, or the nearest one about which the section is star-shaped
    distance: float  # D: the far field's distance from the wall
    wake: float  # the cut's length behind the trailing edge
    le_arc: float
    gap: float  # the base's width (0 when sharp)
    base_lower: np.ndarray
    base_upper: np.ndarray
    splits: tuple  # O-grid: the ring arcs where blocks meet (lower|section, section|upper)


@functools.lru_cache(maxsize=16)
def _setup(key: tuple) -> _Setup:
    from meshgen.geometry.airfoil_curve import leading_edge_arc, points_at, trailing_edge
    from meshgen.geometry.airfoils import load_section, naca4_section

    v = _values(key)
    _check(v)
    if SECTION_FILE is not None:
        section = FILE_SECTION
    elif v["thickness"] != 0:  # a 4-digit section of continuous parameters: closed trailing edge, a C-grid
        section = naca4_section(v["camber"], v["camber_position"], v["thickness"])
    else:
        designation = _designation(v)
        try:
            section = load_section(designation, closed_te=bool(v["sharp"]) and designation != "tmr0012")
        except (GeometryError, ParameterError) as exc:
            raise GeometryError(f"geometry 'airfoil': naca={v['naca']:g}: {exc}") from None
    edge = trailing_edge(section)
    alpha = math.radians(v["alpha"])
    turn = np.array([[math.cos(alpha), math.sin(alpha)], [-math.sin(alpha), math.cos(alpha)]])
    pivot = np.array([0.25, 0.0])
    le_arc, length = leading_edge_arc(section), section.length
    fractions = 0.5 + np.array([0.0, *np.repeat(np.arange(1, 46), 2) * np.tile([-0.01, 0.01], 45)])  # 0.5, 0.49, 0.51, ...
    lower, upper = points_at(section, le_arc * (1.0 - fractions)), points_at(section, le_arc + fractions * (length - le_arc))
    middle = 0.5 * (lower + upper)  # the centres tried, nearest mid-chord first (the first star-shaped one is taken)
    te = 0.5 * (edge.lower + edge.upper)
    gap = 0.0 if edge.sharp else float(np.linalg.norm(edge.upper - edge.lower))
    splits = (0.5 * gap + 0.5 * le_arc, 0.5 * gap + 0.5 * (le_arc + length))
    setup = _Setup(
        section, bool(edge.sharp), turn, pivot, te, middle[0],
        float(v["farfield"]), float(v["wake"] or v["farfield"]), le_arc, gap, edge.lower, edge.upper, splits,
    )  # fmt: skip
    for centre in middle:  # a strongly cambered thin section may not be star-shaped about its mid-chord point
        setup = dataclasses.replace(setup, centre=centre)
        if _is_star(setup):
            return setup
    raise GeometryError(
        "geometry 'airfoil': the section is not star-shaped about any point of its mean line from 5 % to 95 % chord (too cambered for its thickness)"
    )


def _turned(setup: _Setup, points: np.ndarray) -> np.ndarray:
    return (points - setup.pivot) @ setup.turn.T + setup.pivot


def _ring_points(setup: _Setup, r: np.ndarray) -> np.ndarray:
    """O-grid: the wall at ring arcs ``r`` (from the base's middle, clockwise), turned."""
    from meshgen.geometry.airfoil_curve import points_at

    half, length = 0.5 * setup.gap, setup.section.length
    out = np.empty((len(r), 2))
    on = (r >= half) & (r <= half + length)
    out[on] = points_at(setup.section, np.clip(r[on] - half, 0.0, length))
    mid = 0.5 * (setup.base_lower + setup.base_upper)
    low = r < half
    out[low] = mid + (setup.base_lower - mid) * (r[low] / half)[:, None]
    high = r > half + length
    out[high] = setup.base_upper + (mid - setup.base_upper) * ((r[high] - half - length) / half)[:, None]
    return out


def _ring_length(setup: _Setup) -> float:
    return setup.section.length + setup.gap


def _polar(setup: _Setup, points: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """The polar angle about the centre, clockwise from the trailing edge: 0 there, about pi at
    the leading edge, 2 pi back at the trailing edge (``lower``: points before the leading edge)."""
    theta_te = math.atan2(*(setup.te - setup.centre)[::-1])
    d = points - setup.centre
    rel = np.mod(theta_te - np.arctan2(d[:, 1], d[:, 0]), 2 * np.pi)
    rel = np.where(lower & (rel > 1.5 * np.pi), rel - 2 * np.pi, rel)
    return np.where(~lower & (rel < 0.5 * np.pi), rel + 2 * np.pi, rel)


def _wall(setup: _Setup, block: str, xi: np.ndarray, turned: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 2) of block ``block``'s wall (or cut) at xi and the unit directions (N, 2) of its
    straight lines, turned by alpha (``turned``) or not."""
    points, direction = _wall_unturned(setup, block, xi)
    if not turned:
        return points, direction
    return _turned(setup, points), direction @ setup.turn.T


_WALLS = {}  # (id(setup), block, xi's bytes) -> (setup, points, directions): a mesh asks for the same nodes several times


def _wall_unturned(setup: _Setup, block: str, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    xi = np.clip(np.asarray(xi, dtype=float), 0.0, 1.0)
    key = (id(setup), block, xi.tobytes())
    cached = _WALLS.get(key)
    if cached is None or cached[0] is not setup:
        if len(_WALLS) > 32:
            _WALLS.clear()
        cached = _WALLS[key] = (setup, *_wall_points(setup, block, xi))
    return cached[1].copy(), cached[2].copy()


def _wall_points(setup: _Setup, block: str, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    from meshgen.geometry.airfoil_curve import points_at

    if setup.sharp:
        if block in ("lower", "upper"):
            run = setup.wake * (1.0 - xi if block == "lower" else xi)
            points = setup.te + np.stack([run, np.zeros_like(run)], axis=1)
            direction = np.tile([0.0, -1.0 if block == "lower" else 1.0], (len(xi), 1))
            return points, direction
        s = xi * setup.section.length
        return _section_directions(setup, points_at(setup.section, s), s <= setup.le_arc, xi == 0.0, xi == 1.0)
    a, b = setup.splits
    start, end = {"lower": (0.0, a), "section": (a, b), "upper": (b, _ring_length(setup))}[block]
    r = start + xi * (end - start)
    points = _ring_points(setup, r)
    direction = points - setup.centre
    return points, direction / np.linalg.norm(direction, axis=1, keepdims=True)


def _section_directions(setup: _Setup, points, lower, first, last) -> tuple[np.ndarray, np.ndarray]:
    """A C-grid's section points (m, 2) (the trailing edge at ``first`` and ``last``) and the unit
    directions of their straight lines: down at the lower trailing edge, turning at half the rate
    of the polar angle (``lower``: points before the leading edge), up at the upper."""
    points[first] = points[last] = setup.te
    phi = -0.5 * np.pi - 0.5 * _polar(setup, points, lower)
    phi = np.where(first, -0.5 * np.pi, np.where(last, 0.5 * np.pi, phi))
    return points, np.stack([np.cos(phi), np.sin(phi)], axis=1)


def _section_at_parameters(setup: _Setup, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``_wall``'s section points and directions at curve parameters ``t`` (m,), not arc fractions."""
    section = setup.section
    return _section_directions(setup, section.shape(t), t <= section.le_parameter, t == 0.0, t == 1.0)


def _is_star(setup: _Setup) -> bool:
    """The straight lines must not cross: the polar angle about ``setup.centre`` increases along the wall."""
    if setup.sharp:
        s = np.linspace(0.0, setup.section.length, 4001)
        points, lower = _wall(setup, "section", s / setup.section.length, turned=False)[0], s <= setup.le_arc
    else:
        r = np.linspace(0.0, _ring_length(setup), 4001)
        points, lower = _ring_points(setup, r), r <= 0.5 * setup.gap + setup.le_arc
    return bool(np.all(np.diff(_polar(setup, points, lower)[1:-1]) > 0))


def boundary(block, points, **values):
    """(N, 2) points on the unit square's boundary -> (N, 2) points of block ``block``: w(xi) + eta D e(xi)."""
    setup = _setup(_key(values))
    wall, direction = _wall(setup, block, points[:, 0])
    return wall + (points[:, 1] * setup.distance)[:, None] * direction


# ---------------------------------------------------------------------------------------------
# node distributions (meshgen.geometry.airfoil_spacing)


def block_coords(dims, **values):
    """The blocks' parametric nodes (``airfoil_spacing.block_coords`` of this section)."""
    return airfoil_spacing.block_coords(_setup(_key(values)), dims, values)


def notes(block_set):
    """One line: the first-cell height (formula, Cf) and the growth ratio that --dims forces."""
    values = block_set.values
    h, how = first_height(values)
    d = np.asarray(block_set.coords[0][1]) * _setup(_key(values)).distance
    ratio = (d[int(values["layers"]) + 1] - d[int(values["layers"])]) / (d[1] - d[0])
    kind = "C-grid" if _setup(_key(values)).sharp else "O-grid"
    return [
        f"airfoil {kind}: first cell {h:.3g} chord ({how}); {len(d) - 1} cells to {d[-1]:g} chords, growth ratio {ratio:.4f} (cap {values['growth']:g})"
    ]


# ---------------------------------------------------------------------------------------------
# the elliptic mesh: near-wall layers marched, the rest solved


_FAR_CURVES = {}  # id(setup) -> (setup, arc -> curve parameter, curve length): the curve of every --dims


def _far_points(setup: _Setup, u: np.ndarray) -> np.ndarray:
    """Points (k, 2) of the far-field curve w + D e (unturned) at curve parameters ``u`` (k,): the
    block's index plus its xi (the section block of a C-grid: its curve parameter), 0 to 3."""
    block = np.minimum(np.floor(u).astype(int), len(blocks) - 1)
    out = np.empty((len(u), 2))
    for b, name in enumerate(blocks):
        on = block == b
        if setup.sharp and name == "section":
            points, direction = _section_at_parameters(setup, u[on] - b)
        else:
            points, direction = _wall_points(setup, name, np.clip(u[on] - b, 0.0, 1.0))
        out[on] = points + setup.distance * direction
    return out


def _far_curve(setup: _Setup):
    """The far-field curve's parameter as a function of its arc length (a monotone C1 interpolant,
    scipy ``PchipInterpolator``, of 4001 points per block) and its length, made once per setup."""
    from scipy.interpolate import PchipInterpolator

    cached = _FAR_CURVES.get(id(setup))
    if cached is not None and cached[0] is setup:
        return cached[1], cached[2]
    u = np.concatenate([b + np.linspace(0.0, 1.0, 4001)[min(b, 1) :] for b in range(len(blocks))])
    dense = _far_points(setup, u)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))])
    if len(_FAR_CURVES) > 16:
        _FAR_CURVES.clear()
    _FAR_CURVES[id(setup)] = (setup, PchipInterpolator(arc, u), float(arc[-1]))
    return _FAR_CURVES[id(setup)][1:]


def far_field(setup: _Setup, coords) -> np.ndarray:
    """The far-field nodes (N + 1, 2) of the row of blocks, unturned: on the boundary map's outer
    curve (w + D e), spaced as the boundary map spaces them but with the logarithm of the spacing
    diffused over ``FARFIELD_SMOOTHING`` cells (the section block's far-field cells are about 15 times longer than
    the wake blocks' where they meet). Each node is the curve at the parameter its arc length maps to
    (``_far_curve``): on the curve, and smooth in the section's parameters (nodes interpolated
    along the dense polyline put kinks of about a chord per unit thickness into the derivatives of
    a family's far-field nodes, ``meshgen.neural.wall_derivatives``)."""
    designed = []
    for block, c in zip(blocks, coords):
        points, direction = _wall(setup, block, np.asarray(c[0]), turned=False)
        designed.append(points + setup.distance * direction)
    designed = np.concatenate([designed[0], designed[1][1:], designed[2][1:]])
    parameter, length = _far_curve(setup)
    spacing = smoothed_spacing(np.linalg.norm(np.diff(designed, axis=0), axis=1), FARFIELD_SMOOTHING)
    out = _far_points(setup, parameter(np.concatenate([[0.0], np.cumsum(spacing)]) * length / spacing.sum()))
    out[0], out[-1] = designed[0], designed[-1]
    return out


def _marched(setup: _Setup, block_set) -> tuple[list, np.ndarray]:
    """The marched layers of the row of blocks (``meshgen.methods.hyperbolic.march``), turned: one
    array (n + 1, m + 1, 2) for the whole row (its first node repeated last for a ring), and the
    block offsets along it."""
    from meshgen.methods.hyperbolic import march

    d = np.asarray(block_set.coords[0][1]) * setup.distance
    walls = [_wall(setup, b, np.asarray(c[0]), turned=False)[0] for b, c in zip(blocks, block_set.coords)]
    curve = np.concatenate([walls[0], walls[1][1:], walls[2][1:]])
    for smoothing in MARCH_SMOOTHING:  # the march's default first; a tight concave trailing-edge corner needs more
        try:
            if setup.sharp:
                marched = march(curve, d, ends=("constant_x", "constant_x"), smoothing=smoothing)
            else:
                marched = march(curve[:-1], d, closed=True, smoothing=smoothing, area_smoothing=0.25)
            break
        except GeometryError as exc:
            error = exc
    else:
        n = sum(len(c[0]) - 1 for c in block_set.coords)
        raise GeometryError(
            f"geometry 'airfoil': --dims N = {n} is too coarse along the wall to march to the far field ({error})"
        ) from None
    if not setup.sharp:
        marched = np.concatenate([marched, marched[:1]])
    return _turned(setup, marched), np.cumsum([0] + [len(w) - 1 for w in walls[:2]])


def blend_weight(values, d) -> np.ndarray:
    """The share (m + 1,) of the straight lines in the mesh at distances ``d`` (m + 1,):
    smoothstep(log(d / BLEND_START) / log(D / BLEND_START)), 0 within ``BLEND_START`` chords."""
    distance = float({**params, **values}["farfield"])
    t = np.clip(np.log(np.maximum(d, BLEND_START) / BLEND_START) / math.log(distance / BLEND_START), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def wall_teacher(block_set):
    """The mesh ``meshgen.neural.wall_map`` learns, per block (n_b, m + 1, 2): the marched layers
    (``_marched``), which ``wall_finish`` turns into the elliptic mesh as ``mesh_elliptic`` does, so
    a network that reproduced them exactly would give the elliptic mesh itself. (Learning the
    finished mesh instead blends it twice, and its far field, where the lines are straight and a
    direction error moves a node by the distance times the error, folds more: 396 inverted cells
    in 7 held-out members of a family against 142 for the same training on the marched layers, by hand.)"""
    setup = _setup(_key(block_set.values))
    marched, offsets = _marched(setup, block_set)
    return [marched[o : o + len(c[0])] for o, c in zip(offsets, block_set.coords)]


def wall_finish(block_set, Xs, check=True):
    """A learned mesh ``Xs`` (per block (n_b, m + 1, 2), the network's image of the elliptic mesh)
    finished as the elliptic mesh is (``_blend``): beyond ``BLEND_START`` chords blended into the
    straight lines to the far-field nodes, nodes at the designed distances, interfaces identical;
    the network's error there fades with the blend weight, and the far field is exact.
    GeometryError for inverted cells with ``check``. Returns the node arrays."""
    return _blend(block_set, Xs, check)


def _blend(block_set, near, check=True):
    """The mesh from the marched layers ``near`` (per block (n_b, m + 1, 2), turned; or a learned
    mesh, ``wall_finish``): the layers beyond ``BLEND_START`` chords blended into straight lines from the wall
    nodes to the far-field nodes (``far_field``: the spacing smoothed), nodes slid along each line
    to the designed distances (``meshgen.methods.clustering.respaced_lines``; the wake cut's lines
    to their own, ``airfoil_spacing.line_distances``), interface nodes made identical. GeometryError
    when a cell is inverted (``check``)."""
    from meshgen.geometry.block_nodes import unify_interfaces
    from meshgen.methods.hyperbolic import cell_areas

    setup = _setup(_key(block_set.values))
    d = np.asarray(block_set.coords[0][1]) * setup.distance
    walls = [_wall(setup, b, np.asarray(c[0]), turned=False)[0] for b, c in zip(blocks, block_set.coords)]
    sizes = [len(w) for w in walls]
    curve = np.concatenate([walls[0], walls[1][1:], walls[2][1:]])
    weight = blend_weight(block_set.values, d)[None, :, None]
    offsets = np.cumsum([0, sizes[0] - 1, sizes[1] - 1])
    curve, far = _turned(setup, curve), _turned(setup, far_field(setup, block_set.coords))  # turning is affine
    lines = curve[:, None] + (d / setup.distance)[None, :, None] * (far - curve)[:, None]
    Xs = [X + weight * (lines[o : o + size] - X) for X, o, size in zip(near, offsets, sizes)]
    Xs = [respaced_lines(X, along, weight[0, :, 0]) for X, along in zip(Xs, airfoil_spacing.line_distances(setup, walls, d))]
    unify_interfaces(block_set, Xs)
    inverted = sum(int(np.sum(cell_areas(X) <= 0)) for X in Xs)
    if inverted and check:
        raise GeometryError(f"geometry 'airfoil': {inverted} cells of the mesh are inverted (try more cells or a smaller growth)")
    return Xs


def mesh_elliptic(block_set, tol=None, max_iter=None, progress=None):
    """The hook of ``meshgen.run.meshing`` for ``--method elliptic``: every layer marched off the
    wall (``meshgen.methods.hyperbolic.march``: first cells of the asked height, grid lines square
    to the wall, ``_marched``), then blended beyond ``BLEND_START`` chords into straight lines
    to the far field (``_blend``: nodes at the designed distances, weight
    smoothstep(log(d / BLEND_START) / log(D / BLEND_START))). No Winslow equations are solved: a
    Winslow outer region keeps harmonic, not designed, wall-normal spacing (logarithmic round the
    front, linear in the wake) and leaves the marched layer at up to 80 degrees. ``tol``,
    ``max_iter``: not used (no iteration). Returns (node arrays per block, info)."""
    start = time.perf_counter()
    d = np.asarray(block_set.coords[0][1])
    marched, offsets = _marched(_setup(_key(block_set.values)), block_set)
    Xs = _blend(block_set, [marched[o : o + len(c[0])] for o, c in zip(offsets, block_set.coords)])
    info = {
        "solver": f"hyperbolic march of all {len(d) - 1} layers, blended into straight lines to the far field beyond {BLEND_START:g} chord",
        "sweeps": 0,
        "iterations": 0,
        "final_update": 0.0,
        "final_residual": 0.0,
        "tol": 0.0 if tol is None else float(tol),
        "converged": True,
        "seconds": time.perf_counter() - start,
    }
    return Xs, info
