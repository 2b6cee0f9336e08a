"""A closed triangulated surface (STL, OBJ, PLY) read as a sweep: of its patches (a multi-solid
ASCII STL's named solids, else the sharp-edge split's, ``surface_patches.split_at_sharp_edges``:
patch1..patchN), two planar ones (the caps) that every other patch touches, the second the
first carried by a rigid motion
(``sweep_read.cap_motions``, ``moved``): a translation, every other triangle parallel to it (the
outline's prism: a triangulated cylinder or prism), or a rotation about an axis, every other
triangle on the surface the first cap's outline sweeps (a bend: ``sweep_stl_turn``).

``read_surface_sweep(path)`` returns what ``sweep_read.read_sweep`` does for a CAD solid (kind
"six", "sweep" or "other", names, volume, box, caps, motion, origin, frame, curves, holes), each
curve's points the outline's own vertices (``linear``: joined by straight lines, so points
interpolated along them lie on the facets; its ``vertices`` their indices, ``patches`` the
linking patches of its edges); the curves break at the outline's sharp corners (turning by more
than ``sweep_read.SHARP_DEGREES``). A bend also has ``sides`` (``sweep_stl_turn.SideMap``: the
outline's points turned, on the linking facets) and its motion the chords' largest ``sag``
(relative to the size). ``caps_found``: two planar patches that every other touches were found
after the sharp-edge split (a refusal then names what they are not; named solids that are no
sweep are the single-block reader's to refuse); ``patch_words`` where the patches come from. Caps match to ``PLANAR`` of the size, or to the
float32 rounding of a file written in float32 (``_rounding``). ``caps`` (a geometry file's two
patch names, ``sweep_yaml``): only that pair, in that order, is tried, by the same checks (kind
"other" with the reason they are not); ``feature_angle``: the sharp-edge split's (degrees).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry.shapes.surface_patches import (
    DEFAULT_FEATURE_ANGLE,
    check_closed,
    patch_corners,
    read_surface,
    split_at_sharp_edges,
    triangle_normals,
)
from meshgen.geometry.shapes.sweep_read import SHARP_DEGREES, cap_motions, moved
from meshgen.geometry.shapes.sweep_stl_turn import positive, turned_sides

__all__ = ["read_surface_sweep"]

PLANAR = 1e-9  # relative to the surface's size: a planar patch's points off its plane


def read_surface_sweep(path, caps=None, feature_angle=None) -> dict:
    """The triangulated surface in ``path`` seen as a straight sweep (module docstring); ``caps``:
    the names of the two patches to try as its caps (first, second), else every pair."""
    path = Path(path)
    surface = read_surface(path)
    named = bool((surface.labels >= 0).any())  # patches of its own (a multi-solid ASCII STL's solids)
    if not named:
        surface = split_at_sharp_edges(surface, DEFAULT_FEATURE_ANGLE if feature_angle is None else feature_angle)
    check_closed(surface, str(path))
    V, T, labels, names = surface.vertices, surface.triangles, surface.labels, surface.names
    box = np.stack([V.min(axis=0), V.max(axis=0)])
    size = float(np.linalg.norm(box[1] - box[0]))
    corners = patch_corners(surface)
    found = {
        "names": tuple(names),
        "volume": abs(float(np.einsum("ij,ij->i", V[T[:, 0]], np.cross(V[T[:, 1]], V[T[:, 2]])).sum()) / 6.0),
        "box": box,
        "face_tags": tuple(range(len(names))),
        "summary": f"{len(names)} {'named patches' if named else 'patches at its sharp edges'} with "
        f"({', '.join(str(len(c)) for c in corners)}) corners",
        "linear": True,
        "patch_words": "the file's named solids" if named else "the sharp-edge split's",
    }
    pair = None
    if caps is not None:
        unknown = [name for name in caps if name not in names]
        if unknown:
            raise GeometryError(f"{path}: 'caps' names no patch '{unknown[0]}' (patches: {', '.join(names)})")
        pair = tuple(names.index(name) for name in caps)
    elif len(names) == 6 and all(len(c) == 4 for c in corners):
        return {**found, "kind": "six"}
    normals = triangle_normals(V, T)
    cross = np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]])
    areas = 0.5 * np.linalg.norm(cross, axis=1)
    vertices_of = [np.unique(T[labels == k]) for k in range(len(names))]
    tolerance = _rounding(V, size)
    planes = []
    for k in range(len(names)):
        normal = (cross[labels == k]).sum(axis=0)
        normal = normal / max(np.linalg.norm(normal), 1e-300)
        centre = (areas[labels == k, None] * V[T[labels == k]].mean(axis=1)).sum(axis=0) / areas[labels == k].sum()
        flat = np.abs((V[vertices_of[k]] - centre) @ normal).max() <= tolerance
        planes.append((flat, normal, centre, areas[labels == k].sum()))
    from scipy.spatial import cKDTree  # when a surface is read, not on every command's path (meshgen --help)

    why, nearest = "no two planar patches that every other patch touches", np.inf
    if pair is not None:
        why = _pair_fault(planes, vertices_of, pair, names)
        if why:
            return {**found, "kind": "other", "reason": why}
    for i, j in [pair] if pair is not None else itertools.combinations(range(len(names)), 2):
        if pair is None and _pair_fault(planes, vertices_of, (i, j), names):
            continue
        others = [k for k in range(len(names)) if k not in (i, j)]
        found["caps_found"] = not named  # a sweep's refusal then says why, not the single block's
        outline = [_boundary_edges(T[labels == c]) for c in (i, j)]
        ends = [V[np.unique(e)] for e in outline]
        nearest_gap = cKDTree(ends[1])  # the second cap's outline vertices
        if nearest == np.inf:  # else a turn that came near says why
            why = f"patches {names[i]} and {names[j]} are planar but not one outline moved along a line or turned about an axis"
        motions = cap_motions(planes[i][1], planes[j][1], planes[i][2], planes[j][2], size, tolerance / size)
        for motion in motions:
            gap = nearest_gap.query(moved(motion, ends[0], 1.0))[0].max() if len(ends[0]) == len(ends[1]) else np.inf
            if gap > tolerance:
                continue
            if motion["kind"] == "translation":
                vector = motion["vector"]
                side = np.isin(labels, others)
                if side.any() and np.abs(normals[side] @ (vector / np.linalg.norm(vector))).max() > 1e-9:
                    continue
            else:
                motion = positive(motion)
            loops = _loops(outline[0])
            if len(loops) > 2:
                return {
                    **found,
                    "kind": "other",
                    "reason": f"{names[i]} and {names[j]} are caps with more than one hole (not meshed yet)",
                }
            origin = planes[i][2]
            velocity = moved(motion, origin[None], 1e-3)[0] - origin  # the sweep's direction at the cap
            normal = planes[i][1] if planes[i][1] @ velocity > 0 else -planes[i][1]
            helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
            e1 = np.cross(helper, normal) / np.linalg.norm(np.cross(helper, normal))
            frame = np.stack([e1, np.cross(normal, e1)])
            edge_patch = _edge_patches(T, labels, i)
            curves = [_curves(V, loop, origin, frame, edge_patch) for loop in loops]
            curves.sort(key=lambda loop: -abs(_area(np.concatenate([c["points"] for c in loop]))))
            motion = {**motion, "gap": gap / size}
            sweep = {**found, "kind": "sweep", "caps": (i, j), "origin": origin, "frame": frame, "centroid": np.zeros(2),
                     "motion": motion, "curves": curves[0], "holes": curves[1:]}  # fmt: skip
            if motion["kind"] == "translation":
                return sweep
            sides, measured = turned_sides(V, T, labels, motion, origin, frame, curves, size, names)
            if sides is None:  # the turn that comes nearest says why
                if measured[0] < nearest:
                    nearest = measured[0]
                    why = f"patches {names[i]} and {names[j]} are planar caps, one the other turned, but {measured[1]}"
                continue
            motion.update(gap=max(gap / size, measured[0]), sag=measured[1])
            return {**sweep, "sides": sides}
    return {**found, "kind": "other", "reason": why}


def _pair_fault(planes, vertices_of, pair, names) -> str:
    """Why the patches ``pair`` (i, j) cannot be a sweep's caps: not planar, touching each other,
    or a third patch that does not touch both; "" when they may be."""
    i, j = pair
    flat = [k for k in pair if not planes[k][0]]
    if flat:
        return f"{names[flat[0]]} is not planar"
    if i == j or np.intersect1d(vertices_of[i], vertices_of[j]).size:
        return "they touch (share a vertex)" if i != j else "they are one patch"
    for k in range(len(names)):
        if k not in pair and not all(np.intersect1d(vertices_of[k], vertices_of[c]).size for c in pair):
            return f"{names[k]} does not touch both"
    return ""


def _rounding(V: np.ndarray, size: float) -> float:
    """How far (length) the file's own rounding may have moved a vertex: ``PLANAR`` of the size,
    or, for float32 coordinates (a binary STL, a PLY), 8 float32 spacings at the largest one."""
    if np.array_equal(V.astype(np.float32).astype(float), V):
        return max(PLANAR * size, 8.0 * float(np.spacing(np.float32(np.abs(V).max()))))
    return PLANAR * size


def _boundary_edges(triangles: np.ndarray) -> np.ndarray:
    """(E, 2) the edges, as the triangles run them, that only one of ``triangles`` (m, 3) has."""
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    key = np.sort(edges, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return edges[counts[inverse.ravel()] == 1]


def _loops(edges: np.ndarray) -> list[np.ndarray]:
    """The closed vertex loops (each (n,), not repeating its start) that the directed ``edges``
    (E, 2) chain into: each loop cut before its smallest vertex and ranked by pointer doubling."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    ids, local = np.unique(edges, return_inverse=True)
    local = local.reshape(-1, 2)
    n = len(ids)
    following = np.empty(n, dtype=np.int64)
    following[local[:, 0]] = local[:, 1]
    _, component = connected_components(coo_matrix((np.ones(len(local)), (local[:, 0], local[:, 1])), shape=(n, n)))
    starts = np.full(component.max() + 1, n)
    np.minimum.at(starts, component, np.arange(n))
    last = following == starts[component]  # the vertex before each loop's start ends it
    jump, rank = np.where(last, np.arange(n), following), np.where(last, 0, 1)
    for _ in range(int(np.ceil(np.log2(max(n, 2)))) + 1):  # rounds of doubling, not vertices
        rank, jump = rank + rank[jump], jump[jump]
    return [ids[np.flatnonzero(component == c)[np.argsort(-rank[component == c])]] for c in range(len(starts))]


def _edge_patches(T, labels, cap: int) -> dict:
    """(a, b) vertex pair of each of the cap's outline edges -> the other patch whose triangle has it."""
    other = labels != cap
    edges = np.concatenate([T[other][:, [0, 1]], T[other][:, [1, 2]], T[other][:, [2, 0]]])
    owners = np.tile(labels[other], 3)
    return dict(zip(map(tuple, np.sort(edges, axis=1).tolist()), owners.tolist()))


def _area(xy: np.ndarray) -> float:
    return 0.5 * float(np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1]))


def _curves(V, loop, origin, frame, edge_patch) -> list:
    """One loop of vertex indices as curves (``sweep_read``'s form, counterclockwise in the
    frame), broken at its sharp corners; one smooth curve if it has none."""
    xy = (V[loop] - origin) @ frame.T
    if _area(xy) < 0:
        loop, xy = loop[::-1], xy[::-1]
    incoming, outgoing = xy - np.roll(xy, 1, axis=0), np.roll(xy, -1, axis=0) - xy
    cosine = (incoming * outgoing).sum(axis=1) / (np.linalg.norm(incoming, axis=1) * np.linalg.norm(outgoing, axis=1))
    sharp = np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))) > SHARP_DEGREES
    starts = np.flatnonzero(sharp) if sharp.any() else np.array([0])
    n, curves = len(loop), []
    for a, b in zip(starts, np.append(starts[1:], starts[0] + n)):
        index = np.arange(a, b + 1) % n
        points = xy[index]
        length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
        patches = [edge_patch[(int(p), int(q))] for p, q in np.sort(np.column_stack([loop[index[:-1]], loop[index[1:]]]), axis=1)]
        curves.append({"fractions": length / length[-1], "points": points, "face": int(patches[0]), "smooth": not sharp[a],
                       "vertices": loop[index], "patches": set(patches)})  # fmt: skip
    return curves
