"""A closed triangulated surface read as a bend: ``sweep_stl``'s two planar caps, the second the
first turned about an axis (``sweep_read.moved``'s rotation), every linking triangle on the
surface the first cap's outline sweeps.

``turned_sides(...)`` checks the linking triangles and returns a ``SideMap``: each linking
vertex gets the parameters (s, theta) of the point of the swept surface it lies on (s the arc
length along its cap loop from the loop's first curve, theta the angle turned), found by turning
it back onto the first cap's plane (``Loop.foot``: the nearest point of the loop); ``SideMap.evaluate`` puts a point of the swept surface, given
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

__all__ = ["CHORD_TOLERANCE", "VERTEX_TOLERANCE", "Loop", "SideMap", "turned_sides"]

VERTEX_TOLERANCE = 1e-6  # relative to the part's size: a linking vertex off the swept surface
CHORD_TOLERANCE = 1e-2  # relative: a linking triangle's centre off it (the facets' chords sag)
AXIS_CLEARANCE = 1e-3  # relative: the outline's least distance from the axis
CANDIDATES = 4  # a projection onto a loop tries the edges of this many nearest samples


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


class Loop:
    """A closed polyline ``points`` (P, 2) of a cap loop (in the cap's frame), ``start`` (P + 1,)
    the arc length at each point from the first (the last: the loop's length), and a k-d tree of
    points along its edges at most a quarter of the mean edge length apart, for ``foot``."""

    def __init__(self, points: np.ndarray):
        from scipy.spatial import cKDTree

        self.points = np.asarray(points, dtype=float)
        self.ends = np.roll(self.points, -1, axis=0)
        lengths = np.linalg.norm(self.ends - self.points, axis=1)
        self.start = np.concatenate([[0.0], np.cumsum(lengths)])
        spacing = self.start[-1] / (4.0 * len(lengths))
        counts = np.ceil(lengths / spacing).astype(np.int64)
        self.sample_edge = np.repeat(np.arange(len(lengths)), counts)
        share = (np.arange(len(self.sample_edge)) - np.repeat(np.cumsum(counts) - counts, counts)) / counts[self.sample_edge]
        edge = self.sample_edge
        self.tree = cKDTree(self.points[edge] + share[:, None] * (self.ends[edge] - self.points[edge]))

    def foot(self, xy: np.ndarray):
        """The nearest point of the loop to each of ``xy`` (N, 2): (its arc length s (N,), the
        distance (N,)), among the edges of the ``CANDIDATES`` nearest samples and their
        neighbours (the exact nearest edge for a point on or near the loop)."""
        xy = np.asarray(xy, dtype=float)
        n = len(self.points)
        near = self.tree.query(xy, k=min(CANDIDATES, self.tree.n))[1].reshape(len(xy), -1)
        edges = (self.sample_edge[near][:, :, None] + np.array([-1, 0, 1])).reshape(len(xy), -1) % n  # (N, C)
        a, b = self.points[edges], self.ends[edges]
        d = b - a
        t = np.clip(((xy[:, None, :] - a) * d).sum(axis=2) / np.maximum((d * d).sum(axis=2), 1e-300), 0.0, 1.0)
        gap = np.linalg.norm(xy[:, None, :] - (a + t[..., None] * d), axis=2)
        best = np.argmin(gap, axis=1)
        rows = np.arange(len(xy))
        edge = edges[rows, best]
        return self.start[edge] + t[rows, best] * (self.start[edge + 1] - self.start[edge]), gap[rows, best]


def _turned_back(points, motion, origin, frame, loop):
    """Each of ``points`` (N, 3) turned back onto the first cap's plane (the angle theta in
    [0, motion angle] that puts it there: of the two, the one nearer the loop) and measured against
    the cap's ``Loop``: (theta (N,), s (N,), distance (N,))."""
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
        s, across = loop.foot(back @ frame.T)
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
    (module docstring): ``loop_of`` patch index -> loop; per loop its ``Loop`` (in the cap's
    frame) and a ``locate.SquareLocator`` over (s / loop length, theta / angle) with the
    triangles' corner points ``values`` (3m, 3)."""

    def __init__(self, loop_of, loops, locators, values):
        self.loop_of, self.loops, self.locators, self.values = loop_of, loops, locators, values

    def evaluate(self, patch: int, xy: np.ndarray, zeta: np.ndarray) -> np.ndarray:
        """(N, 3) the points on the linking triangles of ``patch`` at the cap-outline points ``xy``
        (N, 2, in the cap's frame, on the loop) turned a share ``zeta`` (N,) of the bend."""
        loop = self.loop_of[patch]
        s, _ = self.loops[loop].foot(xy)
        query = np.column_stack([s / self.loops[loop].start[-1], np.asarray(zeta, dtype=float)])
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
    loop_of, outlines, locators, values, worst = {}, [], [], [], [0.0, 0.0]
    for index, loop in enumerate(loops):
        ids = np.concatenate([curve["vertices"][:-1] for curve in loop])
        outline = Loop((vertices[ids] - origin) @ frame.T)
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
        theta, s, distance = _turned_back(vertices[used], motion, origin, frame, outline)
        centres = vertices[side].mean(axis=1)
        for k, limit, what in ((0, VERTEX_TOLERANCE, "vertices"), (1, CHORD_TOLERANCE, "triangles' centres")):
            found = distance if k == 0 else _turned_back(centres, motion, origin, frame, outline)[2]  # vertices first
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
        total = outline.start[-1]
        seam = np.ptp(params[:, :, 0], axis=1) > 0.5 * total  # triangles across s = 0: unwrapped upwards
        params[:, :, 0] += np.where(seam[:, None] & (params[:, :, 0] < 0.5 * total), total, 0.0)
        copies = params[seam] - np.array([total, 0.0])  # and a copy of each below s = 0
        params = np.concatenate([params, copies])
        corners = np.concatenate([side, side[seam]])
        uv = (params / np.array([total, motion["angle"]])).reshape(-1, 2)
        locators.append(build_locator(uv, np.arange(len(uv)).reshape(-1, 3)))
        values.append(vertices[corners].reshape(-1, 3))
        outlines.append(outline)
    return SideMap(loop_of, outlines, locators, values), tuple(worst)
