"""Hyperbolic marching of a 2D grid off a wall curve: the near-wall part of airfoil C- and O-grids,
down to first cells of 1e-6 chord (y+ about 1) at aspect ratios of 1e5.

Method (Steger & Chaussee 1980, with Chan & Steger's dissipation, as in Construct2D and pyHyp): layer
``k + 1`` follows from layer ``k`` by the orthogonality and cell-area conditions
``x_xi x_eta + y_xi y_eta = 0`` and ``x_xi y_eta - y_xi x_eta = dA``, linearised about layer ``k``
(``r_eta`` predicted as the local normal times the step): ``(I + C d_xi - eps_i dd_xi) dr = B^-1 g``,
``C = B^-1 A`` from the 2x2 coefficient blocks, ``d_xi`` the central difference, ``dd_xi`` the second
difference (implicit dissipation); one block-tridiagonal system of 2x2 blocks
per layer (periodic for a closed curve), solved as a sparse system (scipy.sparse.linalg.spsolve).
Details of this implementation:

- the tangent at a node is that of the circle through it and its two neighbours, so a circle of any point
  spacing and a straight line of any spacing march exactly;
- the solved step ``dr`` gives each node's direction; its length is set to the layer's marching step
  (``distances[k+1] - distances[k]``) times the area-smoothing factor ``w``: ``w`` is 1 at the wall and
  redistributes the cell areas (relative to the wall's point spacing) between neighbours farther out, so
  every wall node's first cell has the requested height and concave pockets fill faster than convex tips;
- dissipation: the implicit coefficient ``eps_i = 2 eps_e``, ``eps_e = smoothing S_l (d / ds)^2 D a`` with
  ``d`` the distance marched, ``ds`` the local point spacing, ``S_l = sqrt(k / (m - 1))`` (zero at the wall),
  ``D`` the grid-convergence sensor (spacing shrinking from one layer to the next) and ``a`` the grid-angle
  function (concave corners): features shorter than about ``sqrt(smoothing) d`` along a layer are smoothed
  out at distance ``d``, the geometric scale of an offset curve. (Chan & Steger scale by the step
  ``N = dh / ds``; that left the concave wake junction of a C-grid's trailing edge to fold.) The same
  ``eps_e`` slides each new layer's nodes along it by an implicit smoothing of its stretch relative to the
  wall's spacing (no node passes another), and an explicit pass across it removes zigzags (kept below 1/4);
- the coupling ``C`` uses the step/spacing ratio capped at 1: beyond, roundoff in it grew into wiggles.
"""

from __future__ import annotations

import numpy as np

from meshgen.errors import GeometryError, ParameterError

__all__ = ["END_CONDITIONS", "cell_areas", "march", "self_crossings"]

# What the first and the last node of an open curve may do (``ends``); a 2-vector is a direction.
END_CONDITIONS = ("free", "constant_x", "constant_y")

_EXPLICIT_CAP = 0.5  # the largest explicit (Jacobi) smoothing coefficient that does not overshoot
_AREA_PASSES = 4  # Jacobi passes of the area smoothing per layer
_COUPLING_CAP = 1.0  # the largest step / spacing ratio in the coupling C (roundoff grows beyond)


def self_crossings(curve: np.ndarray, closed: bool, chunk: int = 256) -> np.ndarray:
    """Index pairs (i, j), i < j, of the segments of ``curve`` (n, 2) whose interiors cross properly
    (each one's ends strictly on both sides of the other's line). Touching points and collinear overlaps
    (the two coincident wake cuts of a C-grid) do not count. Shape (count, 2)."""
    a = curve if closed else curve[:-1]
    b = np.roll(curve, -1, axis=0) if closed else curve[1:]
    s = len(a)
    found = []
    for start in range(0, s, chunk):  # rows in chunks: O(s^2) memory would not fit long curves
        i = np.arange(start, min(start + chunk, s))[:, None]
        j = np.arange(s)[None, :]

        def side(p, q, r):
            return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

        pa, pb, qa, qb = a[i], b[i], a[j], b[j]
        proper = (side(pa, pb, qa) * side(pa, pb, qb) < 0) & (side(qa, qb, pa) * side(qa, qb, pb) < 0)
        proper &= j > i
        ii, jj = np.nonzero(proper)
        found.append(np.stack([ii + start, jj], axis=1))
    return np.concatenate(found) if found else np.zeros((0, 2), dtype=int)


def cell_areas(nodes: np.ndarray, closed: bool = False) -> np.ndarray:
    """Signed areas (n - 1 or n, m) of the quadrilateral cells of a grid ``nodes`` (n, m + 1, 2): half the
    cross product of the diagonals, positive where (xi, eta) is right-handed."""
    nxt = np.roll(nodes, -1, axis=0) if closed else nodes[1:]
    cur = nodes if closed else nodes[:-1]
    d1 = nxt[:, 1:] - cur[:, :-1]
    d2 = cur[:, 1:] - nxt[:, :-1]
    return 0.5 * (d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])


def _check_curve(curve, closed: bool) -> np.ndarray:
    try:
        c = np.array(curve, dtype=float)
    except (TypeError, ValueError):
        raise GeometryError("hyperbolic march: the curve is not an array of numbers") from None
    if c.ndim != 2 or c.shape[1] != 2:
        raise GeometryError(f"hyperbolic march: the curve must have shape (n, 2), got {c.shape}")
    if len(c) < 3:
        raise GeometryError(f"hyperbolic march: the curve needs at least 3 points, got {len(c)}")
    if not np.isfinite(c).all():
        raise GeometryError("hyperbolic march: the curve has NaN or infinite coordinates")
    chords = np.diff(np.concatenate([c, c[:1]]) if closed else c, axis=0)
    short = np.nonzero(np.hypot(chords[:, 0], chords[:, 1]) == 0)[0]
    if len(short):
        what = " (a closed curve does not repeat its first point)" if closed and short[0] == len(c) - 1 else ""
        raise GeometryError(f"hyperbolic march: points {short[0]} and {(short[0] + 1) % len(c)} of the curve coincide{what}")
    crossings = self_crossings(c, closed)
    if len(crossings):
        i, j = crossings[0]
        raise GeometryError(f"hyperbolic march: the curve crosses itself (segments {i} and {j})")
    return c


def _check_distances(distances) -> np.ndarray:
    try:
        d = np.array(distances, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError("distances", "{name} is not an array of numbers") from None
    if d.ndim != 1 or len(d) < 2:
        raise ParameterError("distances", f"{{name}} must be a 1D array of at least 2 values, got shape {d.shape}")
    if not np.isfinite(d).all():
        raise ParameterError("distances", "{name} has NaN or infinite values")
    if d[0] != 0 or not (np.diff(d) > 0).all():
        raise ParameterError("distances", "{name} must start at 0 and increase strictly")
    return d


def _end_direction(condition, normal: np.ndarray, which: str) -> np.ndarray | None:
    """Unit direction (2,) in which an end node marches, on the marching side; None for 'free'."""
    if isinstance(condition, str):
        if condition == "free":
            return None
        if condition not in END_CONDITIONS:
            raise ParameterError(
                "ends", f"{{name}}: unknown end condition '{condition}' ({', '.join(END_CONDITIONS)} or a direction)"
            )
        axis = 1 if condition == "constant_x" else 0
        direction = np.zeros(2)
        direction[axis] = 1.0
    else:
        direction = np.array(condition, dtype=float)
        if direction.shape != (2,) or not np.isfinite(direction).all() or not direction.any():
            raise ParameterError("ends", f"{{name}}: the {which} end's direction must be a nonzero 2-vector, got {condition!r}")
        direction /= np.hypot(*direction)
        if direction @ normal <= 0.1:
            raise GeometryError(f"hyperbolic march: the {which} end's direction does not point to the marching side")
    cosine = direction @ normal
    if abs(cosine) <= 0.1:
        raise GeometryError(f"hyperbolic march: '{condition}' at the {which} end runs along the curve's end segment")
    return direction * np.sign(cosine)


def _metrics(r: np.ndarray, closed: bool):
    """Unit tangents (n, 2) (of the circle through each node and its neighbours), unit left normals
    (n, 2) and local spacings (n,) (mean of the two chords; the one chord at an open curve's ends)."""
    prev = np.roll(r, 1, axis=0)
    nxt = np.roll(r, -1, axis=0)
    a = np.linalg.norm(r - prev, axis=1)
    b = np.linalg.norm(nxt - r, axis=1)
    if not closed:
        a[0], b[-1] = b[0], a[-1]
    # b * e_prev + a * e_next = (b / a) (r - prev) + (a / b) (next - r): the circumcircle's tangent
    tangent = (b / a)[:, None] * (r - prev) + (a / b)[:, None] * (nxt - r)
    spacing = 0.5 * (a + b)
    if not closed:
        tangent[0], tangent[-1] = r[1] - r[0], r[-1] - r[-2]
        spacing[0], spacing[-1] = a[0], b[-1]
    length = np.linalg.norm(tangent, axis=1)
    if (length == 0).any():
        raise GeometryError("hyperbolic march: the curve folds back on itself (a cusp of zero angle)")
    tangent /= length[:, None]
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    return tangent, normal, spacing


def _turning_cosine(r: np.ndarray, closed: bool) -> np.ndarray:
    """Per node, the cosine squared of half the angle between its two chords on the marching side, for
    concave corners (the marching side's angle below 180 degrees); 0 at convex and straight nodes."""
    e1 = r - np.roll(r, 1, axis=0)
    e2 = np.roll(r, -1, axis=0) - r
    cross = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]  # > 0: a left turn, concave for a left march
    with np.errstate(invalid="ignore", divide="ignore"):  # an open curve's wrapped ends may coincide
        cosine = (e1 * e2).sum(1) / (np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1))
    cosine = np.nan_to_num(cosine, nan=1.0)
    turn = np.arccos(np.clip(cosine, -1.0, 1.0))  # 180 degrees minus the angle on the marching side
    half = 0.5 * (np.pi - turn)
    out = np.where(cross > 0, np.cos(half) ** 2, 0.0)
    if not closed:
        out[0] = out[-1] = 0.0
    return out


def _pattern(n: int, closed: bool):
    """Block columns (n, 3) of each node's row: (i - 1, i, i + 1), periodic for a closed curve; an open
    curve's end rows hold the end node and its next two (room for the 'free' end's extrapolation)."""
    i = np.arange(n)
    cols = np.stack([(i - 1) % n, i, (i + 1) % n], axis=1)
    if not closed:
        cols[0] = (1, 0, 2)
        cols[-1] = (n - 2, n - 1, n - 3)
    rows = np.broadcast_to(2 * i[:, None, None, None] + np.arange(2)[None, None, :, None], (n, 3, 2, 2))
    columns = np.broadcast_to(2 * cols[:, :, None, None] + np.arange(2)[None, None, None, :], (n, 3, 2, 2))
    return rows.ravel(), columns.ravel()


def _neighbour_mean(values: np.ndarray, closed: bool) -> np.ndarray:
    mean = 0.5 * (np.roll(values, 1) + np.roll(values, -1))
    if not closed:
        mean[0], mean[-1] = values[1], values[-2]
    return mean


def _redistributed(layer: np.ndarray, wall_chords: np.ndarray, eps: np.ndarray, closed: bool) -> np.ndarray:
    """``layer`` (n, 2) with its nodes slid along it (the polyline through them): the arc length ``s``
    solves ``s - eps m L s = s_old``, ``L`` the second difference in the wall's arc length (chords
    ``wall_chords``, n - 1 or n), ``m`` the mean wall chord at each node: implicit smoothing of the
    layer's stretch ds/d(wall arc length), whose fixed points are the wall's spacing ratios. An open
    curve's ends stay; a closed curve is periodic."""
    from scipy.sparse import csc_matrix
    from scipy.sparse.linalg import spsolve

    n = len(layer)
    ring = np.concatenate([layer, layer[:1]]) if closed else layer
    chords = np.linalg.norm(np.diff(ring, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(chords)])
    total = arc[-1]
    after = wall_chords if closed else np.concatenate([wall_chords, wall_chords[-1:]])
    before = np.roll(after, 1) if closed else np.concatenate([wall_chords[:1], wall_chords])
    mean = 0.5 * (before + after)
    lower = eps * mean / before
    upper = eps * mean / after
    diag = 1.0 + lower + upper
    rhs = arc[:n].copy()
    i = np.arange(n)
    if closed:  # s_{-1} = s_{n-1} - total, s_n = s_0 + total
        rhs[0] -= lower[0] * total
        rhs[-1] += upper[-1] * total
    else:
        diag[0] = diag[-1] = 1.0
        lower[0] = upper[0] = lower[-1] = upper[-1] = 0.0
    rows = np.concatenate([i, i, i])
    cols = np.concatenate([i, (i - 1) % n, (i + 1) % n])
    matrix = csc_matrix((np.concatenate([diag, -lower, -upper]), (rows, cols)), shape=(n, n))
    s = spsolve(matrix, rhs)
    if closed:
        s = np.mod(s, total)
    x = np.interp(s, arc, ring[:, 0])
    y = np.interp(s, arc, ring[:, 1])
    out = np.stack([x, y], axis=1)
    if not closed:
        out[0], out[-1] = layer[0], layer[-1]
    return out


def _smoothed(layer: np.ndarray, eps: np.ndarray, closed: bool) -> np.ndarray:
    """``layer`` (n, 2) after one explicit smoothing pass across it of coefficients ``eps`` (n,): each
    node moves along its normal by the difference of the layer's local curvature from its neighbours'
    (a zigzag is removed, a uniform curvature kept: a circle stays a circle). An open curve's ends stay."""
    tangent, normal, _ = _metrics(layer, closed)
    prev, nxt = np.roll(layer, 1, axis=0), np.roll(layer, -1, axis=0)
    across = ((0.5 * (prev + nxt) - layer) * normal).sum(1)
    if not closed:
        across[0], across[-1] = across[1], across[-2]
    bumps = across - _neighbour_mean(across, closed)
    shift = np.minimum(eps, 0.5 * _EXPLICIT_CAP)[:, None] * bumps[:, None] * normal
    if not closed:
        shift[0] = shift[-1] = 0.0
    return layer + shift


def march(
    curve, distances, closed: bool = False, ends=None, smoothing: float = 0.05, area_smoothing: float = 0.0, check: bool = True
) -> np.ndarray:
    """Grid nodes (n, m + 1, 2) marched off the wall ``curve`` (n, 2) to the cumulative marching distances
    ``distances`` (m + 1,), from 0 at the wall: ``nodes[:, 0]`` is ``curve`` (bit for bit),
    ``nodes[i, k]`` the node of grid line ``i`` on layer ``k``; each grid line is a polyline whose length
    from the wall to layer ``k`` is ``distances[k]`` near the wall (area smoothing rescales the steps
    of later layers by up to a factor 2 either way; 1 on a circle and on a straight line).

    Side: an open curve marches to its left (the (xi, eta) grid right-handed, cell areas positive); a
    closed curve (last point not repeating the first) marches outward whichever its orientation (cell
    areas positive for a clockwise curve, negative for a counter-clockwise one). A C-grid's curve runs
    along the wake cut's lower side to the trailing edge, round the section (lower side, leading edge,
    upper side) and back along the cut's upper side; the cut's two sides may coincide point for point.

    ``ends`` (open curves only): the conditions of the first and the last node, a pair of 'free' (the
    step extrapolated linearly from the next two nodes), 'constant_x' (the node moves along y, away
    from the curve: a C-grid's outflow boundary), 'constant_y' (moves along x) or a direction (dx, dy)
    pointing to the marching side; default ('free', 'free').
    ``smoothing``: the dissipation coefficient (explicit; the implicit one is twice it): the default 0.05
    fits airfoil O- and C-grids; concave corners (an inner right angle, notches) need about 0.5;
    ``area_smoothing``: the Jacobi coefficient of the cell-area smoothing (default 0, none: with it the
    concave trailing-edge junction of a C-grid folds; an O-grid takes 0.25).
    ``check``: raise GeometryError when a cell of the result is inverted.
    Units are the curve's; GeometryError / ParameterError for bad input (fewer than 3 points, NaN,
    coincident neighbours, a curve crossing itself, distances not increasing from 0).
    """
    from scipy.sparse import csc_matrix
    from scipy.sparse.linalg import spsolve

    c = _check_curve(curve, closed)
    d = _check_distances(distances)
    for name, value, top in (("smoothing", smoothing, 10.0), ("area_smoothing", area_smoothing, 0.5)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value <= top:
            raise ParameterError(name, f"{{name}} must be a number from 0 to {top}, got {value!r}")
    if closed and ends is not None:
        raise ParameterError("ends", "{name} applies to an open curve only (a closed curve has no ends)")
    ends = ("free", "free") if ends is None else ends
    if isinstance(ends, str) or len(ends) != 2:
        raise ParameterError("ends", f"{{name}} must be a pair (first, last), got {ends!r}")
    n, m = len(c), len(d) - 1
    # a counter-clockwise closed curve is marched reversed, so that outward is its left
    reverse = closed and (c[:, 0] * np.roll(c[:, 1], -1) - np.roll(c[:, 0], -1) * c[:, 1]).sum() > 0
    wall = c[::-1] if reverse else c
    nodes = np.empty((n, m + 1, 2))
    nodes[:, 0] = wall
    _, normal0, spacing0 = _metrics(wall, closed)
    directions = (
        [None, None] if closed else [_end_direction(e, normal0[j], w) for e, j, w in zip(ends, (0, -1), ("first", "last"))]
    )
    wall_chords = np.linalg.norm(np.diff(np.concatenate([wall, wall[:1]]) if closed else wall, axis=0), axis=1)
    rows, columns = _pattern(n, closed)
    eye = np.eye(2)
    spacing_before = spacing0
    for k in range(m):
        r = nodes[:, k]
        tangent, normal, spacing = _metrics(r, closed)
        step = d[k + 1] - d[k]
        ramp = np.sqrt(k / (m - 1)) if m > 1 else 0.0
        # area smoothing: the spacing relative to the wall's, averaged with the neighbours'
        stretch = spacing / spacing0
        smooth = stretch.copy()
        for _ in range(_AREA_PASSES):
            smooth = (1 - area_smoothing) * smooth + area_smoothing * _neighbour_mean(smooth, closed)
        weight = np.clip(1.0 + ramp * (smooth / stretch - 1.0), 0.5, 2.0)
        ratio = step / spacing
        converging = np.clip((spacing_before / spacing) ** 2, 0.1, 10.0)
        angle = 1.0 / (1.0 - np.minimum(_turning_cosine(r, closed), 0.9))
        eps_e = smoothing * ramp * (d[k + 1] / spacing) ** 2 * converging * angle
        eps_i = 2.0 * eps_e
        # C = B^-1 A with r_xi = spacing * tangent, r_eta = weight * step * normal: a reflection times N w
        s2 = 2 * tangent[:, 0] * tangent[:, 1]
        c2 = tangent[:, 0] ** 2 - tangent[:, 1] ** 2
        coupling = (weight * np.minimum(ratio, _COUPLING_CAP))[:, None, None] * np.stack(
            [np.stack([-s2, c2], -1), np.stack([c2, s2], -1)], -2
        )
        blocks = np.empty((n, 3, 2, 2))
        blocks[:, 0] = -0.5 * coupling - eps_i[:, None, None] * eye
        blocks[:, 1] = (1.0 + 2.0 * eps_i)[:, None, None] * eye
        blocks[:, 2] = 0.5 * coupling - eps_i[:, None, None] * eye
        rhs = (weight * step)[:, None] * normal
        if not closed:
            for j, direction in zip((0, -1), directions):
                blocks[j] = 0.0
                blocks[j, 1] = eye
                if direction is None:  # free: dr_0 - 2 dr_1 + dr_2 = 0
                    blocks[j, 0], blocks[j, 2] = -2.0 * eye, eye
                    rhs[j] = 0.0
                else:
                    rhs[j] = weight[j] * step * direction
        matrix = csc_matrix((blocks.ravel(), (rows, columns)), shape=(2 * n, 2 * n))
        dr = spsolve(matrix, rhs.ravel()).reshape(n, 2)
        for j, direction in zip((0, -1), directions):
            if direction is not None:
                dr[j] = rhs[j]  # exactly along the given direction (the solve may leave 1e-17 across)
        forward = (dr * normal).sum(1)
        if not (forward > 0).all():
            i = int(np.argmin(forward))
            raise GeometryError(
                f"hyperbolic march: layer {k + 1} turns back at node {i} (a corner too tight for the steps and smoothing)"
            )
        dr *= (weight * step / np.linalg.norm(dr, axis=1))[:, None]
        nodes[:, k + 1] = _redistributed(_smoothed(r + dr, eps_e, closed), wall_chords, eps_e, closed)
        spacing_before = spacing
    if check:
        areas = cell_areas(nodes, closed)
        bad = np.argwhere(areas <= 0)
        if len(bad):
            i, k = bad[bad[:, 1].argmin()]
            raise GeometryError(
                f"hyperbolic march: cell {i} of layer {k + 1} is inverted (smaller growth or more smoothing may help)"
            )
    if reverse:
        nodes = nodes[::-1].copy()
    nodes[:, 0] = c
    return nodes
