"""A CAD solid read as a sweep (in the CAD process: gmsh, OpenCASCADE): two planar cap faces
joined by linking faces, the second cap the first moved by a rigid motion, a translation (a
straight sweep) or a rotation about an axis (a bend, a revolve), the linking faces the cap's
outline carried along it (``moved``).

``read_sweep(path, content_hash, caps)`` returns plain values only (they cross the CAD process's
pipe). ``caps``: two face names (a geometry file's, ``sweep_yaml``): only that pair, in that order,
is tried as the caps, by the same checks; the answer is then "other" with the reason they are not.

    kind         "six" (six four-cornered faces: the single block of ``cad``), "sweep", or "other"
    summary      one line: how many faces of how many sides each
    reason       why it is no sweep ("other" only)
    names        per CAD face, its patch name (the face's CAD name, else face1..faceN)
    volume, box  OCC's volume of the solid; its bounding box (2, 3)
    caps         (first cap, second cap) face indices; the second is the first carried by ``motion``
    origin, frame  the first cap's plane: a point (3,) and two orthonormal axes (2, 3), the frame's
                 normal (frame[0] x frame[1]) along the sweep
    centroid     the first cap's centre of area in the frame (2,)
    curves       the first cap's boundary loop, counterclockwise in the frame: per curve its points
                 (K, 2) in the frame at arc-length fractions ``fractions`` (K,), the index of the
                 linking face it bounds, and whether the loop turns smoothly at its start
    holes        the loops of the first cap's holes (at most one), as ``curves``, counterclockwise too

A "loft" (two planar, parallel caps, maybe of different shapes, whose loops have as many curves,
the k-th of each bounding the k-th linking face, a ruled one: a circle of four arcs lofted to a
square: ``_find_loft``) has ``caps``, ``origin``, ``frame`` as above, ``origins`` (each cap's
centre of area (2, 3)), ``loops`` (per cap its loop, as ``curves`` but about that cap's centre,
the k-th curves of both on one linking face: a straight line joins their points at equal
fractions, the ruling) and ``gap`` (how far the rulings came from the faces, relative to the
solid's size).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry.shapes.cad import gmsh_model

__all__ = ["CURVE_SAMPLES", "SHARP_DEGREES", "cap_motions", "moved", "read_sweep"]

CURVE_SAMPLES = 1025  # points per cap curve sent to meshgen (a cubic spline through them there)
DENSE_SAMPLES = 8001  # parameter samples per curve for its arc length
SHARP_DEGREES = 20.0  # the loop turns by more than this at a corner; less: a smooth joint
TOLERANCE = 1e-7  # relative to the solid's size: the caps' and the extrusion's agreement
SNAP = TOLERANCE  # a curve's points further than this (relative) off a face it bounds are put on both
_POINTS: dict = {}  # (model, curve, count) -> _curve_points's answer, for one read_sweep
MASS_AGREE = 1e-9  # a planar face's OCC area and centre are kept within this (relative) of its outline's
SNAP_ROUNDS = 3  # projections onto each face in turn (one is exact where the faces meet at right angles)


def read_sweep(path, content_hash: str = "", caps=None) -> dict:
    """The solid of the CAD file ``path`` seen as a straight sweep (module docstring); ``caps``:
    the names of the two faces to try as its caps (first, second), else every pair."""
    path = Path(path)
    gmsh = gmsh_model(path, f"meshgen-{content_hash[:16]}")
    _POINTS.clear()
    volumes = gmsh.model.getEntities(3)
    if len(volumes) != 1:
        raise GeometryError(f"{path} holds {len(volumes)} solids; a sweep is one solid")
    faces = [abs(tag) for dim, tag in gmsh.model.getBoundary(volumes, oriented=False) if dim == 2]
    curves_of = [{abs(tag) for _, tag in gmsh.model.getBoundary([(2, face)], oriented=False, combined=False)} for face in faces]
    sides = [len(gmsh.model.getBoundary([(2, face)], oriented=False, combined=False)) for face in faces]
    names = []
    for k, face in enumerate(faces):
        name = gmsh.model.getEntityName(2, face).split("/")[-1].strip().replace(" ", "_")
        names.append(name if name and name not in names else f"face{k + 1}")
    pair = None if caps is None else tuple(_face_index(path, names, name) for name in caps)
    box = np.array(gmsh.model.getBoundingBox(-1, -1)).reshape(2, 3)
    size = float(np.linalg.norm(box[1] - box[0]))
    found = {
        "names": tuple(names),
        "volume": float(gmsh.model.occ.getMass(3, volumes[0][1])),
        "box": box,
        "face_tags": tuple(faces),
        "summary": f"{len(faces)} faces with ({', '.join(map(str, sides))}) sides",
    }
    if len(faces) == 6 and all(n == 4 for n in sides):  # one block, unless its caps' outlines turn smoothly
        loft = _find_loft(gmsh, faces, curves_of, size, pair)
        if pair is not None and loft is not None:  # named caps: a loft of them, or why not
            return {**found, "kind": "loft", **loft}
        if pair is not None:
            why = _pair_fault(gmsh, faces, curves_of, pair, names) or "they are no loft's caps (ruled linking faces)"
            return {**found, "kind": "other", "reason": why}
        smooth = loft is not None and any(c["smooth"] for loop in loft["loops"] for c in loop)
        return {**found, "kind": "loft", **loft} if smooth else {**found, "kind": "six"}
    caps, reason = _find_caps(gmsh, faces, curves_of, size, pair, names)
    if caps is None and "not of one area" in reason:
        loft = _find_loft(gmsh, faces, curves_of, size, pair)
        if loft is not None:
            return {**found, "kind": "loft", **loft}
    if caps is None:
        return {**found, "kind": "other", "reason": reason}
    first, second, motion = caps
    return {**found, "kind": "sweep", "caps": (first, second), "motion": motion,
            **_cap_loop(gmsh, faces, first, motion)}  # fmt: skip


def moved(motion: dict, points: np.ndarray, t) -> np.ndarray:
    """(N, 3) ``points`` (N, 3) carried a share ``t`` (scalar or (N,)) of the way along the sweep
    ``motion``: {"kind": "translation", "vector" (3,)} or {"kind": "rotation", "point" (3,),
    "axis" (3,) unit, "angle" radians} (Rodrigues' formula); read_sweep's also has "gap", how far
    (relative to the solid's size) the cap's outline carried along it came from the second cap's
    outline and the linking faces."""
    t = np.broadcast_to(np.asarray(t, dtype=float), points.shape[:1])[:, None]
    if motion["kind"] == "translation":
        return points + t * motion["vector"]
    point, axis, angle = motion["point"], motion["axis"], t * motion["angle"]
    v = points - point
    return point + v * np.cos(angle) + np.cross(axis, v) * np.sin(angle) + (v @ axis)[:, None] * axis * (1 - np.cos(angle))


def cap_motions(n_i, n_j, c_i, c_j, size, tolerance: float = 1e-9):
    """The rigid motions that could carry a cap (unit normal ``n_i`` (3,), centroid ``c_i`` (3,))
    onto the other: the translation c_j - c_i when the normals are parallel, else rotations about
    the axis square to both normals through the point that carries c_i to c_j (to ``tolerance``
    of the solid's ``size``), either way round."""
    axis = np.cross(n_i, n_j)
    if np.linalg.norm(axis) < 1e-6:
        return [{"kind": "translation", "vector": c_j - c_i}]
    axis /= np.linalg.norm(axis)
    base = float(np.arctan2(np.cross(n_i, n_j) @ axis, n_i @ n_j))
    found = []
    for angle in (base, base - np.pi, base - 2 * np.pi, base + np.pi):
        cos, sin = np.cos(angle), np.sin(angle)
        rotation = cos * np.eye(3) + sin * np.cross(np.eye(3), axis) + (1 - cos) * np.outer(axis, axis)
        point = np.linalg.lstsq(np.eye(3) - rotation, c_j - rotation @ c_i, rcond=None)[0]
        if np.linalg.norm((np.eye(3) - rotation) @ point - (c_j - rotation @ c_i)) < tolerance * size:
            found.append({"kind": "rotation", "point": point, "axis": axis, "angle": float(angle)})
    return found


def _face_index(path, names, name) -> int:
    if name not in names:
        raise GeometryError(f"{path}: 'caps' names no face '{name}' (faces: {', '.join(names)})")
    return names.index(name)


def _pair_fault(gmsh, faces, curves_of, pair, names=None) -> str:
    """Why the faces ``pair`` (i, j) cannot be a sweep's caps: not planar, touching each other, or a
    third face that does not touch both; "" when they may be (``names``: the faces' names, for the
    words; else "face k")."""
    i, j = pair
    name = (lambda k: names[k]) if names is not None else (lambda k: f"face {k + 1}")
    flat = [k for k in pair if gmsh.model.getType(2, faces[k]) != "Plane"]
    if flat:
        return f"{name(flat[0])} is not planar ({gmsh.model.getType(2, faces[flat[0]])})"
    if i == j or curves_of[i] & curves_of[j]:
        return "they touch (share an edge)" if i != j else "they are one face"
    for k in range(len(faces)):
        if k not in pair and not (curves_of[k] & curves_of[i] and curves_of[k] & curves_of[j]):
            return f"{name(k)} does not touch both"
    return ""


def _find_caps(gmsh, faces, curves_of, size, pair=None, names=None):
    """((first, second, motion), "") for the first pair of faces that are caps of a sweep by a
    rigid motion (a translation or a rotation: ``moved``), else (None, why no pair is); ``pair``
    (i, j): that pair only, in that order (why not in ``names``' words)."""
    mass = {}  # face index -> (area, centre): planar faces', as needed
    why = "no two planar faces that every other face touches"
    if pair is not None:
        why = _pair_fault(gmsh, faces, curves_of, pair, names)
        if why:
            return None, why
    for i, j in [pair] if pair is not None else itertools.combinations(range(len(faces)), 2):
        if pair is None and _pair_fault(gmsh, faces, curves_of, (i, j)):
            continue
        others = [k for k in range(len(faces)) if k not in (i, j)]
        both = f"{names[i]} and {names[j]}" if pair is not None and names else f"faces {i + 1} and {j + 1}"
        for k in (i, j):
            mass[k] = mass[k] if k in mass else _plane_mass(gmsh, faces, k)
        areas = {k: mass[k][0] for k in (i, j)}
        if abs(areas[i] - areas[j]) > 1e-6 * max(areas[i], areas[j]):
            why = f"{both} could be caps but are not of one area"
            continue
        if len(gmsh.model.occ.getCurveLoops(faces[i])[0]) > 2:
            return None, f"{both} are caps with more than one hole (not meshed yet)"
        centres = [mass[k][1] for k in (i, j)]
        samples = np.concatenate([_curve_points(gmsh, curve, 17)[1] for curve in sorted(curves_of[i])])
        why = f"{both} are planar but not one shape moved along a line or turned about an axis"
        for motion in cap_motions(_normal(gmsh, faces[i]), _normal(gmsh, faces[j]), *centres, size):
            gaps = [_outline_distance(gmsh, curves_of[j], moved(motion, samples, 1.0))]
            if gaps[0] > TOLERANCE * size:
                continue
            for curve in curves_of[i]:
                link = next(k for k in others if curve in curves_of[k])
                points = _curve_points(gmsh, curve, 9)[1]
                between = np.concatenate([moved(motion, points, t) for t in (0.25, 0.5, 0.75)])
                gaps.append(_distance(gmsh, faces[link], between))
            if max(gaps) <= TOLERANCE * size:
                return (i, j, {**motion, "gap": max(gaps) / size}), ""
            why = f"{both} are caps of a sweep along another path (a twist, a helix, a spline)"
    return None, why


def _plane_mass(gmsh, faces, k: int):
    """(area, centre of area (3,)) of the planar face ``faces[k]`` from its boundary loops' points
    (``_loop``: on the faces they bound), by the polygon formulas at every point and at every
    other one, extrapolated (Richardson: the polygon's error goes as the spacing squared). OCC's
    own mass of an IGES face whose edge OCC rebuilt (``_on_faces``) is that edge's, off by up to
    1e-4 of it, too far to match two caps: OCC's unless they differ by more than ``MASS_AGREE``."""
    normal = _normal(gmsh, faces[k])
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    e1 = np.cross(helper, normal) / np.linalg.norm(np.cross(helper, normal))
    frame = np.stack([e1, np.cross(normal, e1)])
    origin = np.array(gmsh.model.occ.getCenterOfMass(2, faces[k]))
    moments = []  # per loop, (area, area times centre (2,)) at every point and at every other one
    for tags in gmsh.model.occ.getCurveLoops(faces[k])[1]:
        loop = _loop(gmsh, faces, k, sorted({abs(int(t)) for t in tags}), origin, frame)
        moments.append([_polygon_moments(np.concatenate([c["points"][::step] for c in loop])) for step in (1, 2)])
    moments.sort(key=lambda m: -m[0][0])  # the outer loop first, the holes (counterclockwise too) after
    area, first = [], []
    for n in (0, 1):
        area.append(moments[0][n][0] - sum(hole[n][0] for hole in moments[1:]))
        first.append(moments[0][n][1] - sum((hole[n][1] for hole in moments[1:]), np.zeros(2)))
    a = (4.0 * area[0] - area[1]) / 3.0
    centre = origin + (4.0 * first[0] - first[1]) / 3.0 / a @ frame
    occ = gmsh.model.occ.getMass(2, faces[k])
    scale = np.sqrt(abs(a))
    if abs(occ - a) <= MASS_AGREE * abs(a) and np.linalg.norm(origin - centre) <= MASS_AGREE * scale:
        return occ, origin  # OCC's, where its edges are exact (STEP)
    return a, centre


def _polygon_moments(xy: np.ndarray):
    """(area, area times centroid (2,)) of the closed polygon ``xy`` (N, 2), counterclockwise."""
    following = np.roll(xy, -1, axis=0)
    cross = xy[:, 0] * following[:, 1] - following[:, 0] * xy[:, 1]
    return 0.5 * float(cross.sum()), ((xy + following) * cross[:, None]).sum(axis=0) / 6.0


def _normal(gmsh, face: int) -> np.ndarray:
    bounds = np.array(gmsh.model.getParametrizationBounds(2, face))
    normal = np.array(gmsh.model.getNormal(face, bounds.mean(axis=0).tolist()))
    return normal / np.linalg.norm(normal)


def _distance(gmsh, face: int, points: np.ndarray) -> float:
    """Largest distance (length) of ``points`` (N, 3) from the CAD face."""
    closest = np.array(gmsh.model.getClosestPoint(2, face, points.ravel().tolist())[0]).reshape(-1, 3)
    return float(np.linalg.norm(closest - points, axis=1).max())


def _outline_distance(gmsh, curves, points: np.ndarray) -> float:
    """Largest distance (length) of ``points`` (N, 3) from the nearest of the CAD ``curves`` (a
    face's outline: a planar face's own closest point is the untrimmed plane's)."""
    nearest = np.full(len(points), np.inf)
    for curve in curves:
        closest = np.array(gmsh.model.getClosestPoint(1, curve, points.ravel().tolist())[0]).reshape(-1, 3)
        nearest = np.minimum(nearest, np.linalg.norm(_on_faces(gmsh, curve, closest) - points, axis=1))
    return float(nearest.max())


def _curve_points(gmsh, curve: int, count: int):
    """(arc-length fractions (count,), points (count, 3)) of a CAD curve from its start, the
    points on both faces it bounds (``_on_faces``); kept per model, curve and count."""
    key = (gmsh.model.getCurrent(), curve, count)
    if key not in _POINTS:
        _POINTS[key] = _sampled(gmsh, curve, count)
    return _POINTS[key]


def _sampled(gmsh, curve: int, count: int):
    low, high = (float(b[0]) for b in gmsh.model.getParametrizationBounds(1, curve))
    t = np.linspace(low, high, DENSE_SAMPLES)
    dense = np.array(gmsh.model.getValue(1, curve, t.tolist())).reshape(-1, 3)
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))])
    at = np.interp(np.linspace(0.0, length[-1], count), length, t)
    points = np.array(gmsh.model.getValue(1, curve, at.tolist())).reshape(-1, 3)
    return np.interp(at, t, length) / length[-1], _on_faces(gmsh, curve, points)


def _on_faces(gmsh, curve: int, points: np.ndarray) -> np.ndarray:
    """``points`` (N, 3) of a CAD curve moved onto the intersection of the faces it bounds
    (projected onto each in turn, ``SNAP_ROUNDS`` times) when they lie off them by more than
    ``SNAP`` of the part's size: an IGES file's edge rebuilt by OCC from a face's parameter-space
    curve (a B-spline within 1e-5 of a circle) and sewn to its neighbour's exact one at that
    tolerance; on an exact edge (STEP) nothing moves."""
    faces = sorted({abs(int(tag)) for tag in gmsh.model.getAdjacencies(1, curve)[0]})
    box = np.array(gmsh.model.getBoundingBox(-1, -1)).reshape(2, 3)
    size = float(np.linalg.norm(box[1] - box[0]))
    probe = points[:: max(1, len(points) // 16)]  # an exact edge (STEP) costs 16 projections per face
    for face in faces:
        probe = np.array(gmsh.model.getClosestPoint(2, face, probe.ravel().tolist())[0]).reshape(-1, 3)
    if np.linalg.norm(probe - points[:: max(1, len(points) // 16)], axis=1).max(initial=0.0) <= SNAP * size:
        return points
    snapped = points
    for _ in range(SNAP_ROUNDS):
        for face in faces:
            snapped = np.array(gmsh.model.getClosestPoint(2, face, snapped.ravel().tolist())[0]).reshape(-1, 3)
    return snapped


def _cap_loop(gmsh, faces, first: int, motion) -> dict:
    """The first cap's frame, centroid, boundary loop and holes' loops (module docstring)."""
    normal = _normal(gmsh, faces[first])
    centre = _plane_mass(gmsh, faces, first)[1]
    velocity = moved(motion, centre[None], 1e-3)[0] - centre  # the sweep's direction at the cap
    normal = normal if normal @ velocity > 0 else -normal
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    e1 = np.cross(helper, normal)
    e1 /= np.linalg.norm(e1)
    frame = np.stack([e1, np.cross(normal, e1)])
    origin = centre
    loops = []
    for tags in gmsh.model.occ.getCurveLoops(faces[first])[1]:
        loops.append(_loop(gmsh, faces, first, sorted({abs(int(t)) for t in tags}), origin, frame))
    loops.sort(key=lambda loop: -_area(np.concatenate([c["points"] for c in loop])))
    return {"origin": origin, "frame": frame, "centroid": np.zeros(2), "curves": loops[0], "holes": loops[1:]}


def _area(xy: np.ndarray) -> float:
    """The signed area (length^2) of the closed polygon ``xy`` (N, 2): positive counterclockwise."""
    return 0.5 * float(np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1]))


def _loop(gmsh, faces, first: int, tags, origin, frame) -> list:
    """One boundary loop of the first cap, counterclockwise in the frame (module docstring)."""
    pieces = []
    for curve in tags:
        fractions, points = _curve_points(gmsh, curve, CURVE_SAMPLES)
        link = next(k for k in range(len(faces)) if k != first and curve in _curves(gmsh, faces[k]))
        pieces.append([fractions, (points - origin) @ frame.T, link])
    loop = [pieces.pop(0)]
    while pieces:  # chain the curves end to start, turning those that run the other way
        end = loop[-1][1][-1]
        gaps = [min(np.linalg.norm(p[1][0] - end), np.linalg.norm(p[1][-1] - end)) for p in pieces]
        piece = pieces.pop(int(np.argmin(gaps)))
        if np.linalg.norm(piece[1][-1] - end) < np.linalg.norm(piece[1][0] - end):
            piece = [1.0 - piece[0][::-1], piece[1][::-1], piece[2]]
        loop.append(piece)
    if _area(np.concatenate([p[1] for p in loop])) < 0:  # clockwise: turn it
        loop = [[1.0 - p[0][::-1], p[1][::-1], p[2]] for p in loop[::-1]]
    curves = []
    for k, (fractions, points, link) in enumerate(loop):
        before = loop[k - 1][1]
        incoming, outgoing = before[-1] - before[-2], points[1] - points[0]
        cosine = incoming @ outgoing / (np.linalg.norm(incoming) * np.linalg.norm(outgoing))
        smooth = bool(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))) < SHARP_DEGREES)
        curves.append({"fractions": fractions, "points": points, "face": int(link), "smooth": smooth})
    return curves


def _curves(gmsh, face: int) -> set:
    return {abs(tag) for _, tag in gmsh.model.getBoundary([(2, face)], oriented=False, combined=False)}


def _find_loft(gmsh, faces, curves_of, size, pair=None):
    """A loft (module docstring) or None: two planar parallel caps without holes whose loops have as
    many curves, the k-th of each on one linking face, which the straight lines between their
    points at equal arc-length fractions (the rulings) lie on; ``pair``: those two faces only."""
    planar = [gmsh.model.getType(2, face) == "Plane" for face in faces]
    for first, second in [pair] if pair is not None else itertools.combinations(range(len(faces)), 2):
        others = [k for k in range(len(faces)) if k not in (first, second)]
        if not (planar[first] and planar[second]) or curves_of[first] & curves_of[second]:
            continue
        if any(len(curves_of[k] & curves_of[first]) != 1 or len(curves_of[k] & curves_of[second]) != 1 for k in others):
            continue
        if len(curves_of[first]) != len(others) or len(curves_of[second]) != len(others):
            continue
        normals = [_normal(gmsh, faces[k]) for k in (first, second)]
        if np.linalg.norm(np.cross(*normals)) > 1e-9:
            continue
        centres = np.array([_plane_mass(gmsh, faces, k)[1] for k in (first, second)])
        normal = normals[0] if normals[0] @ (centres[1] - centres[0]) > 0 else -normals[0]
        helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
        e1 = np.cross(helper, normal) / np.linalg.norm(np.cross(helper, normal))
        frame = np.stack([e1, np.cross(normal, e1)])
        loops = [_loop(gmsh, faces, k, sorted(curves_of[k]), centres[n], frame) for n, k in enumerate((first, second))]
        turn = [c["face"] for c in loops[1]].index(loops[0][0]["face"])
        loops[1] = loops[1][turn:] + loops[1][:turn]
        if [c["face"] for c in loops[0]] != [c["face"] for c in loops[1]]:
            continue
        gaps = []
        for a, b in zip(*loops):
            ends = [centres[n] + c["points"][::32] @ frame for n, c in enumerate((a, b))]
            between = np.concatenate([(1 - t) * ends[0] + t * ends[1] for t in (0.25, 0.5, 0.75)])
            gaps.append(_distance(gmsh, faces[a["face"]], between))
        if max(gaps) > TOLERANCE * size:
            continue
        return {"caps": (first, second), "origin": centres[0], "origins": centres, "frame": frame, "loops": loops,
                "gap": max(gaps) / size}  # fmt: skip
    return None
