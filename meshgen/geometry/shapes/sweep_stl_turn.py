"""A closed triangulated surface read as a bend: ``sweep_stl``'s two planar caps, the second the
first turned about an axis (``sweep_read.moved``'s rotation), every linking triangle on the
surface the first cap's outline sweeps.

``turned_sides(...)`` checks the linking triangles and returns a ``SideMap``: each linking
vertex gets the parameters (s, theta) of the point of the swept surface it lies on (s the arc
length along its cap loop from the loop's first curve, theta the angle turned), found by turning
it back onto the first cap's plane; ``SideMap.evaluate`` puts a point of the swept surface, given
by its cap-outline point and the share zeta of the turn, on the file's triangle holding those
parameters (``locate``: a bucket grid, barycentric coordinates clipped), so every node of a block
face on the outline lies on a facet however the file triangulated the sides. Checked: every
linking vertex within ``VERTEX_TOLERANCE`` of the swept surface, every linking triangle's centre
within ``CHORD_TOLERANCE`` (a chord's sag: the facets cut the curved sides), both relative to the
part's size, and the outline clear of the axis.
"""

from __future__ import annotations

import numpy as np

from meshgen.geometry.shapes.locate import build_locator

__all__ = ["CHORD_TOLERANCE", "VERTEX_TOLERANCE", "SideMap", "turned_sides"]

VERTEX_TOLERANCE = 1e-6  # relative to the part's size: a linking vertex off the swept surface
CHORD_TOLERANCE = 1e-2  # relative: a linking triangle's centre off it (the facets' chords sag)
AXIS_CLEARANCE = 1e-3  # relative: the outline's least distance from the axis
PAIRS = 1 << 21  # (point, polyline edge) pairs per chunk of a projection


def positive(motion: dict) -> dict:
    """The rotation ``motion`` with its angle made positive (the axis turned round if it was not)."""
    if motion["angle"] >= 0:
        return dict(motion)
    return {**motion, "axis": -np.asarray(motion["axis"]), "angle": -float(motion["angle"])}


def _turned(points: np.ndarray, point, axis, angle) -> np.ndarray:
    """(N, 3) ``points`` (N, 3) turned by ``angle`` (N,) radians about the axis through ``point``
    along the unit ``axis`` (Rodrigues' formula)."""
    v = points - point
    cos, sin = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return point + v * cos + np.cross(axis, v) * sin + (v @ axis)[:, None] * axis * (1.0 - cos)


def _foot(xy: np.ndarray, polyline: np.ndarray, start: np.ndarray):
    """The nearest point of the closed ``polyline`` (P, 2) to each of ``xy`` (N, 2): (its arc
    length s (N,) from the polyline's first point, by the edges' starting lengths ``start``
    (P + 1,), and the distance (N,)); in chunks of ``PAIRS`` (point, edge) pairs."""
    a, b = polyline, np.roll(polyline, -1, axis=0)
    d = b - a
    length2 = np.maximum((d * d).sum(axis=1), 1e-300)
    s, distance = np.empty(len(xy)), np.empty(len(xy))
    step = max(1, PAIRS // len(polyline))
    for lo in range(0, len(xy), step):  # chunks of points, not single points
        p = xy[lo : lo + step, None, :]
        t = np.clip(((p - a) * d).sum(axis=2) / length2, 0.0, 1.0)
        gap = np.linalg.norm(p - (a + t[..., None] * d), axis=2)
        edge = np.argmin(gap, axis=1)
        rows = np.arange(len(edge))
        s[lo : lo + step] = start[edge] + t[rows, edge] * (start[edge + 1] - start[edge])
        distance[lo : lo + step] = gap[rows, edge]
    return s, distance


def _turned_back(points, motion, origin, frame, polyline, start):
    """Each of ``points`` (N, 3) turned back onto the first cap's plane (the angle theta in
    [0, motion angle] that puts it there: of the two, the one nearer the loop) and measured against
    the loop ``polyline`` (P, 2, in the cap's frame): (theta (N,), s (N,), distance (N,))."""
    point, axis, angle = motion["point"], motion["axis"], motion["angle"]
    normal = np.cross(frame[0], frame[1])
    v = points - point
    along = v @ axis
    a = v @ normal - along * (normal @ axis)
    b = np.cross(axis, v) @ normal
    c = along * (normal @ axis)
    radius = np.maximum(np.hypot(a, b), 1e-300)
    # n . R(-theta) v = a cos(theta) - b sin(theta) + c = radius cos(theta + beta) + c = n . (origin - point)
    beta = np.arctan2(b, a)
    spread = np.arccos(np.clip((normal @ (origin - point) - c) / radius, -1.0, 1.0))
    best = None
    for theta in (-beta + spread, -beta - spread):
        theta = np.clip(np.mod(theta - 0.5 * angle + np.pi, 2 * np.pi) - np.pi + 0.5 * angle, 0.0, angle)
        back = _turned(points, point, axis, -theta) - origin
        s, across = _foot(back @ frame.T, polyline, start)
        distance = np.hypot(across, back @ normal)
        if best is None:
            best = [theta, s, distance]
        else:
            nearer = distance < best[2]
            for k, value in enumerate((theta, s, distance)):
                best[k] = np.where(nearer, value, best[k])
    return tuple(best)


class SideMap:
    """The linking triangles of a bend as functions of (s, theta), one locator per cap loop
    (module docstring): ``loop_of`` patch index -> loop; per loop its ``polylines`` (P, 2, in the
    cap's frame), ``starts`` (P + 1,) arc lengths, and a ``locate.SquareLocator`` over
    (s / loop length, theta / angle) with the triangles' corner points ``values`` (3m, 3)."""

    def __init__(self, loop_of, polylines, starts, locators, values):
        self.loop_of, self.polylines, self.starts = loop_of, polylines, starts
        self.locators, self.values = locators, values

    def evaluate(self, patch: int, xy: np.ndarray, zeta: np.ndarray) -> np.ndarray:
        """(N, 3) the points on the linking triangles of ``patch`` at the cap-outline points ``xy``
        (N, 2, in the cap's frame, on the loop) turned a share ``zeta`` (N,) of the bend."""
        loop = self.loop_of[patch]
        s, _ = _foot(np.asarray(xy, dtype=float), self.polylines[loop], self.starts[loop])
        query = np.column_stack([s / self.starts[loop][-1], np.asarray(zeta, dtype=float)])
        return self.locators[loop].evaluate(self.values[loop], query)


def turned_sides(vertices, triangles, labels, motion, origin, frame, loops, size: float, names):
    """(the ``SideMap`` of the bend ``motion`` (a rotation, angle positive) whose first cap has
    the frame ``origin`` (3,), ``frame`` (2, 3) and the boundary ``loops`` (``sweep_stl``'s
    curves, each with its outline ``vertices`` and linking ``patches``), (the linking vertices'
    and the triangles' centres' largest distances from the swept surface over ``size``)), or
    (None, (how far off over the tolerance, why the linking triangles are no such bend's)).
    ``vertices`` (n, 3), ``triangles`` (m, 3), ``labels`` (m,) the patch of each, ``size`` the
    part's size (length), ``names`` the patch names."""
    point, axis = motion["point"], motion["axis"]
    words = f"turned {np.degrees(motion['angle']):.6g} deg about an axis"
    loop_of, polylines, starts, locators, values, worst = {}, [], [], [], [], [0.0, 0.0]
    for index, loop in enumerate(loops):
        ids = np.concatenate([curve["vertices"][:-1] for curve in loop])
        polyline = (vertices[ids] - origin) @ frame.T
        edges = np.linalg.norm(np.roll(polyline, -1, axis=0) - polyline, axis=1)
        start = np.concatenate([[0.0], np.cumsum(edges)])
        v = vertices[ids] - point
        clearance = np.linalg.norm(v - np.outer(v @ axis, axis), axis=1).min()
        if clearance < AXIS_CLEARANCE * size:
            return None, (
                np.inf,
                f"the cap's outline comes within {clearance / size:.1e} of the part's size of the axis it is {words} about",
            )
        patches = set()
        for curve in loop:
            patches.update(curve["patches"])
        loop_of.update({patch: index for patch in patches})
        side = triangles[np.isin(labels, sorted(patches))]
        used, corner = np.unique(side, return_inverse=True)
        theta, s, distance = _turned_back(vertices[used], motion, origin, frame, polyline, start)
        centres = vertices[side].mean(axis=1)
        sag = _turned_back(centres, motion, origin, frame, polyline, start)[2]
        for k, (found, limit, what) in enumerate(
            ((distance, VERTEX_TOLERANCE, "vertices"), (sag, CHORD_TOLERANCE, "triangles' centres"))
        ):
            worst[k] = max(worst[k], float(found.max()) / size)
            if found.max() > limit * size:
                at = (vertices[used] if k == 0 else centres)[int(np.argmax(found))]
                return None, (
                    found.max() / size / limit,
                    f"the linking {what} of {', '.join(names[p] for p in sorted(patches))} leave the surface the cap's "
                    f"outline sweeps {words} (by {found.max() / size:.2g} of the part's size, at "
                    f"({', '.join(f'{c:.6g}' for c in at)}); at most {limit:g})",
                )
        params = np.column_stack([s, theta])[corner.reshape(-1, 3)]  # (m, 3, 2) per corner
        total = start[-1]
        seam = np.ptp(params[:, :, 0], axis=1) > 0.5 * total  # triangles across s = 0: unwrapped upwards
        params[:, :, 0] += np.where(seam[:, None] & (params[:, :, 0] < 0.5 * total), total, 0.0)
        copies = params[seam] - np.array([total, 0.0])  # and a copy of each below s = 0
        params = np.concatenate([params, copies])
        corners = np.concatenate([side, side[seam]])
        uv = (params / np.array([total, motion["angle"]])).reshape(-1, 2)
        locators.append(build_locator(uv, np.arange(len(uv)).reshape(-1, 3)))
        values.append(vertices[corners].reshape(-1, 3))
        polylines.append(polyline)
        starts.append(start)
    return SideMap(loop_of, polylines, starts, locators, values), tuple(worst)
