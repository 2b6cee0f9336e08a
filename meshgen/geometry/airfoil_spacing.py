"""The node spacing of the ``airfoil`` geometry's grids (``geometries/airfoil.py``): the grid
family's levels, the first cell from y+, the wall-normal distances, the parametric nodes of the
blocks (C-grid: the wake cut's and round the section; O-grid: round the ring), a node on each
surface's crest, and the wake cut's normal distances.

Lengths are in chords. ``values`` is the geometry's parameter dict; ``setup`` its ``_Setup`` (the
section, the trailing edge, the far field's distance D, the wake's length, the turn by alpha).

Two rules keep OpenFOAM's checkMesh under its aspect-ratio limit (1000) on y+ 1 grids. checkMesh
takes a 2D cell's aspect ratio as the larger over the smaller of its face areas' summed x and y
components, which is the cell's length over its height only where the cell runs along x or y:

- the wake cut's lines (``line_distances``): the wall's distances at the trailing edge, and
  downstream every cell raised so that the first is the cut's streamwise cell over the trailing
  edge's aspect ratio (``WAKE_ASPECT`` at least) high (``wall_spacing.cut_normal_distances``);
  kept at the wall's first height out to the outflow, the cut's cells reached 2.7e7 on the TMR
  grid at 1000 chords;
- a surface's crest (its point farthest from the chord line, where the wall runs along x), where
  its cell is longer than ``CREST_ASPECT`` first heights: a node on it (``section_nodes``), so
  that its two cells slope by half the wall's curvature times their length and checkMesh reads
  each as l / (h + k l^2 / 2), not l / h (the TMR grid's crest cell, 0.0137 chord long, read 1150
  with the crest inside it, 290 beside a node on it); shortened only where that still passes
  ``CREST_ASPECT`` (thin sections, fine levels). Elsewhere the wall slopes and checkMesh reads at
  most about 1 / slope. The true aspect ratio of the mid-chord wall cells (3,100 on the TMR grid)
  is not capped: at 1000 that needs 457 cells round the section, N = 639 (83,709 cells at M = 131)
  where the grid has 456 (59,736). On a grid turned by alpha the crests are the turned wall's
  (where it runs along x after the turn): the section's nodes are its own distribution with those
  crests as nodes, the rest of the grid the unturned one turned (448 x 128 at y+ 1, checkMesh's
  reading at alpha 5: 1,567 with the unturned crests as nodes, under 800 with the turned ones).
"""

from __future__ import annotations

import math

import numpy as np

from meshgen.errors import ParameterError
from meshgen.geometry.airfoil_curve import chordwise_distribution, crest_arcs, points_at
from meshgen.geometry.wall_spacing import cut_normal_distances, first_cell_height, minimal_cell_count, wall_normal_distances

__all__ = [
    "CREST_ASPECT",
    "LEVEL_RATIO",
    "WAKE_ASPECT",
    "block_coords",
    "design_ratio",
    "first_height",
    "level_dims",
    "level_scale",
    "line_distances",
    "normal_distances",
    "section_nodes",
]

LEVEL_RATIO = 1.5  # cells per direction from one grid of a family to the next finer (DPW)
WAKE_SHARE = 0.2  # the least share of N on each side of a C-grid's wake cut
MIN_SECTION_CELLS = 16
MIN_BASE_CELLS = 4  # across a blunt trailing edge (an even count: the base's middle is a node)
RATIO_MARGIN = 0.95  # the wall-normal growth is designed to 1 + 0.95 (cap - 1): the march and the
# solve move the spacing of some lines by up to a few tenths of a percent, and the mesh must stay under the cap
WAKE_ASPECT = 100.0  # the wake cut's cells grow in height where longer than this for it (or the trailing edge's)
CREST_ASPECT = 800.0  # the most checkMesh may read in a surface's crest cells (its limit: 1000; section_nodes)


def level_scale(values) -> float:
    """The factor (2/3)^K of every designed length at grid level K = ``level`` (DPW's family rule)."""
    return LEVEL_RATIO ** -int(values.get("level", 0.0))


def level_dims(values, dims) -> tuple[int, int]:
    """The cell counts (N, M) at grid level K: round(1.5^K N), round(1.5^K M)."""
    return tuple(round(LEVEL_RATIO ** int(values.get("level", 0.0)) * int(k)) for k in dims)


def first_height(values) -> tuple[float, str]:
    """The first-cell height (chords) at the grid level and how it was found (one phrase)."""
    scale = level_scale(values)
    at_level = "" if scale == 1 else f", times (2/3)^{int(values['level'])} at level {int(values['level'])}"
    if values["first_height"] > 0:
        return float(values["first_height"]) * scale, "as given" + at_level
    try:
        cell = first_cell_height(values["yplus"], values["reynolds"])
    except ParameterError as exc:
        raise ParameterError("yplus" if exc.parameter == "y_plus" else exc.parameter, exc.template) from None
    return cell.height * scale, (
        f"y+ {values['yplus']:g} at Re {values['reynolds']:.3g}: h = y+ / (Re sqrt(Cf/2)), Cf = (2 log10 Re - 0.65)^-2.3 = {cell.cf:.4g}"
        + at_level
    )


def design_ratio(cap: float) -> float:
    """The growth ratio the wall-normal distances are designed to under the cap: 1 + 0.95 (cap - 1)."""
    return 1.0 + RATIO_MARGIN * (cap - 1.0)


def normal_distances(values, cells: int) -> tuple[np.ndarray, float]:
    """The wall-normal node distances (cells+1,) from 0 to D and the growth ratio they take."""
    h, _ = first_height(values)
    cap, layers, distance = design_ratio(values["growth"]), int(values["layers"]), float(values["farfield"])
    smallest = minimal_cell_count(h, distance, cap, layers)
    if cells < smallest:
        raise ParameterError(
            "dims",
            f"{{name}}: M = {cells} cells cannot reach the far field ({distance:g} chords) from a first cell of {h:.3g} "
            f"with growth ratios <= {values['growth']:g}: the smallest M that works is {smallest}"
            + (f" (at level {int(values['level'])}: M is round(1.5^K M) of --dims)" if values.get("level") else ""),
        )
    return wall_normal_distances(h, distance, cap, layers, cells=cells)


def _split_at(r: np.ndarray, arc: float, first: int, last: int) -> int:
    """Move node nearest ``arc`` among r[first..last] onto it, stretching its neighbours linearly."""
    j = first + 1 + int(np.argmin(np.abs(r[first + 1 : last] - arc)))
    lo, hi = r[first], r[last]
    r[first : j + 1] = lo + (r[first : j + 1] - lo) * (arc - lo) / (r[j] - lo)
    r[j : last + 1] = arc + (r[j : last + 1] - r[j]) * (hi - arc) / (hi - r[j])
    return j


def section_nodes(setup, cells: int, le_h: float, te_h: float, h: float) -> np.ndarray:
    """Arc lengths (cells + 1,) of the nodes round the section (``chordwise_distribution``). Where a
    surface's cell over its crest (its point farthest along the vertical of the turned grid, where
    the wall runs along x once turned by alpha: ``setup.turn``) is longer than
    ``CREST_ASPECT`` first heights ``h``, checkMesh could read it as that long for its height: then
    each crest is a node, and checkMesh reads its two cells, of length l, as l / (h + k l^2 / 2) (k
    the wall's curvature there: they slope by k l / 2); where that still passes ``CREST_ASPECT``,
    the crest's cells are shortened to the length it reads ``CREST_ASPECT`` at (the smaller root,
    2 A h / (1 + sqrt(1 - 2 k A^2 h))). Otherwise the distribution is ``chordwise_distribution``'s."""
    up = np.asarray(setup.turn[1], dtype=float)  # the turned grid's y in the section's frame: turn @ up = (0, 1)
    s = chordwise_distribution(setup.section, cells, le_h, te_h)
    arcs = crest_arcs(setup.section, up)
    a, caps, step = CREST_ASPECT, [math.inf, math.inf], 1e-4 * setup.section.length
    if all(arc is None or np.interp(arc, 0.5 * (s[1:] + s[:-1]), np.diff(s)) <= a * h for arc in arcs):
        return s
    s = chordwise_distribution(setup.section, cells, le_h, te_h, crest=(math.inf, up))
    for side, arc in enumerate(arcs):
        if arc is None:
            continue
        k = int(np.argmin(np.abs(s - arc)))
        length = max(s[k + 1] - s[k], s[k] - s[k - 1])
        heights = points_at(setup.section, np.array([arc - step, arc, arc + step])) @ up
        curvature = abs(heights[0] - 2.0 * heights[1] + heights[2]) / step**2
        if length / (h + 0.5 * curvature * length**2) > a:
            caps[side] = 2.0 * a * h / (1.0 + math.sqrt(max(1.0 - 2.0 * curvature * a * a * h, 0.0)))
    if min(caps) < math.inf:
        s = chordwise_distribution(setup.section, cells, le_h, te_h, crest=(caps, up))
    return s


def block_coords(setup, dims, values) -> dict:
    """{block: [xi nodes, eta nodes]} (1D, 0 to 1) of the blocks at --dims ``dims`` (N, M) and
    grid level: eta the wall-normal distances over D; C-grid: the wake's share of N on each side
    of the cut (the cut's streamwise nodes from the trailing-edge spacing), the rest round the
    section; O-grid: the ring, base included, split at the middle of each surface."""
    n, m = level_dims(values, dims)
    h = first_height(values)[0]
    eta = normal_distances(values, m)[0] / setup.distance
    te_h, le_h = values["te_spacing"] * level_scale(values), values["le_spacing"] * level_scale(values)
    if setup.sharp:
        cap = design_ratio(values["growth"])
        least = minimal_cell_count(te_h, setup.wake, cap, 1)
        wake_cells = max(least, round(WAKE_SHARE * n))
        if n - 2 * wake_cells < MIN_SECTION_CELLS:
            smallest = max(2 * least + MIN_SECTION_CELLS, math.ceil((MIN_SECTION_CELLS + 1) / (1 - 2 * WAKE_SHARE)))
            raise ParameterError(
                "dims", f"{{name}}: N = {n} is too few for the section and its wake: the smallest N that works is {smallest}"
            )
        wake = wall_normal_distances(te_h, setup.wake, cap, 1, cells=wake_cells)[0] / setup.wake
        around = section_nodes(setup, n - 2 * wake_cells, le_h, te_h, h) / setup.section.length
        return {"lower": [1.0 - wake[::-1], eta], "section": [around, eta], "upper": [wake, eta]}
    base = max(MIN_BASE_CELLS, 2 * math.ceil(setup.gap / (2 * te_h)))
    if n - base < MIN_SECTION_CELLS:
        raise ParameterError(
            "dims", f"{{name}}: N = {n} is too few round the section: the smallest N that works is {base + MIN_SECTION_CELLS}"
        )
    half = 0.5 * setup.gap
    s = section_nodes(setup, n - base, le_h, te_h, h)
    r = np.concatenate(
        [
            np.linspace(0.0, half, base // 2 + 1)[:-1],
            half + s,
            half + setup.section.length + np.linspace(0.0, half, base // 2 + 1)[1:],
        ]
    )
    le = base // 2 + int(np.argmin(np.abs(s - setup.le_arc)))
    a, b = setup.splits
    ja = _split_at(r, a, base // 2, le)
    jb = _split_at(r, b, le, base // 2 + len(s) - 1)
    total = setup.section.length + setup.gap  # the ring's length
    return {
        "lower": [r[: ja + 1] / a, eta],
        "section": [(r[ja : jb + 1] - a) / (b - a), eta],
        "upper": [(r[jb:] - b) / (total - b), eta],
    }


def line_distances(setup, walls, d) -> list:
    """The designed distances of each block's grid lines (chords): ``d`` (m + 1,) round the section;
    along a C-grid's wake cut (``walls`` the blocks' wall or cut nodes, (n_b, 2) each) one row per
    line, (n_b, m + 1), every cell raised so that the first is the cut's streamwise cell at the
    line (the longer of its two) over A high, A the trailing edge's aspect ratio (its cut cell over
    the first height) or ``WAKE_ASPECT`` where larger (``wall_spacing.cut_normal_distances``): the
    trailing edge's line keeps ``d`` (it is the section block's too), and downstream the cut's
    cells stay about A long for their height."""
    if not setup.sharp:
        return [d, d, d]
    out = []
    for cut, te in zip((walls[0], walls[2]), (-1, 0)):
        chords = np.linalg.norm(np.diff(cut, axis=0), axis=1)
        spacing = np.maximum(np.concatenate([chords[:1], chords]), np.concatenate([chords, chords[-1:]]))
        out.append(cut_normal_distances(d, spacing, max(chords[te] / d[1], WAKE_ASPECT)))
    return [out[0], d, out[1]]
