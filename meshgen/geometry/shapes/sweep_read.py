"""A CAD solid read as a straight sweep (in the CAD process: gmsh, OpenCASCADE): two cap faces
joined by linking faces, the second cap the first moved by one vector.

``read_sweep(path, content_hash)`` returns plain values only (they cross the CAD process's pipe):

    kind         "six" (six four-cornered faces: the single block of ``cad``), "sweep", or "other"
    summary      one line: how many faces of how many sides each
    reason       why it is no sweep ("other" only)
    names        per CAD face, its patch name (the face's CAD name, else face1..faceN)
    volume, box  OCC's volume of the solid; its bounding box (2, 3)
    caps         (first cap, second cap) face indices; the second is the first moved by ``translation`` (3,)
    origin, frame  the first cap's plane: a point (3,) and two orthonormal axes (2, 3), the frame's
                 normal (frame[0] x frame[1]) along the translation
    centroid     the first cap's centre of area in the frame (2,)
    curves       the first cap's boundary loop, counterclockwise in the frame: per curve its points
                 (K, 2) in the frame at arc-length fractions ``fractions`` (K,), the index of the
                 linking face it bounds, and whether the loop turns smoothly at its start
    holes        the loops of the first cap's holes (at most one), as ``curves``, counterclockwise too
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry.shapes.cad import gmsh_model

__all__ = ["CURVE_SAMPLES", "SHARP_DEGREES", "read_sweep"]

CURVE_SAMPLES = 1025  # points per cap curve sent to meshgen (a cubic spline through them there)
DENSE_SAMPLES = 8001  # parameter samples per curve for its arc length
SHARP_DEGREES = 20.0  # the loop turns by more than this at a corner; less: a smooth joint
TOLERANCE = 1e-7  # relative to the solid's size: the caps' and the extrusion's agreement


def read_sweep(path, content_hash: str = "") -> dict:
    """The solid of the CAD file ``path`` seen as a straight sweep (module docstring)."""
    path = Path(path)
    gmsh = gmsh_model(path, f"meshgen-{content_hash[:16]}")
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
    box = np.array(gmsh.model.getBoundingBox(-1, -1)).reshape(2, 3)
    size = float(np.linalg.norm(box[1] - box[0]))
    found = {
        "names": tuple(names),
        "volume": float(gmsh.model.occ.getMass(3, volumes[0][1])),
        "box": box,
        "face_tags": tuple(faces),
        "summary": f"{len(faces)} faces with ({', '.join(map(str, sides))}) sides",
    }
    if len(faces) == 6 and all(n == 4 for n in sides):
        return {**found, "kind": "six"}
    caps, reason = _find_caps(gmsh, faces, curves_of, size)
    if caps is None:
        return {**found, "kind": "other", "reason": reason}
    first, second, translation = caps
    return {**found, "kind": "sweep", "caps": (first, second), "translation": translation,
            **_cap_loop(gmsh, faces, first, translation)}  # fmt: skip


def _find_caps(gmsh, faces, curves_of, size):
    """((first, second, translation (3,)), "") for the first pair of faces that are caps of a
    straight sweep, else (None, why no pair is)."""
    planar = [gmsh.model.getType(2, face) == "Plane" for face in faces]
    areas = [gmsh.model.occ.getMass(2, face) for face in faces]
    why = "no two planar faces that every other face touches"
    for i, j in itertools.combinations(range(len(faces)), 2):
        if not (planar[i] and planar[j]) or curves_of[i] & curves_of[j]:
            continue
        others = [k for k in range(len(faces)) if k not in (i, j)]
        if not all(curves_of[k] & curves_of[i] and curves_of[k] & curves_of[j] for k in others):
            continue
        n_i, n_j = _normal(gmsh, faces[i]), _normal(gmsh, faces[j])
        if np.linalg.norm(np.cross(n_i, n_j)) > 1e-6 or abs(areas[i] - areas[j]) > 1e-6 * max(areas[i], areas[j]):
            why = f"faces {i + 1} and {j + 1} could be caps but are not parallel or not of one area"
            continue
        translation = np.array(gmsh.model.occ.getCenterOfMass(2, faces[j])) - np.array(
            gmsh.model.occ.getCenterOfMass(2, faces[i])
        )
        if abs(float(translation @ n_i)) < 1e-6 * size:
            continue
        if len(gmsh.model.occ.getCurveLoops(faces[i])[0]) > 2:
            return None, f"faces {i + 1} and {j + 1} are caps with more than one hole (not meshed yet)"
        samples = np.concatenate([_curve_points(gmsh, curve, 17)[1] for curve in sorted(curves_of[i])])
        if _distance(gmsh, faces[j], samples + translation) > TOLERANCE * size:
            why = f"faces {i + 1} and {j + 1} are parallel but not one shape moved along a line"
            continue
        straight = True
        for curve in curves_of[i]:
            link = next(k for k in others if curve in curves_of[k])
            points = _curve_points(gmsh, curve, 9)[1]
            moved = np.concatenate([points + t * translation for t in (0.25, 0.5, 0.75)])
            straight &= _distance(gmsh, faces[link], moved) <= TOLERANCE * size
        if not straight:
            why = f"faces {i + 1} and {j + 1} are caps of a curved or twisted sweep (only straight sweeps are meshed yet)"
            continue
        return (i, j, translation), ""
    return None, why


def _normal(gmsh, face: int) -> np.ndarray:
    bounds = np.array(gmsh.model.getParametrizationBounds(2, face))
    normal = np.array(gmsh.model.getNormal(face, bounds.mean(axis=0).tolist()))
    return normal / np.linalg.norm(normal)


def _distance(gmsh, face: int, points: np.ndarray) -> float:
    """Largest distance (length) of ``points`` (N, 3) from the CAD face."""
    closest = np.array(gmsh.model.getClosestPoint(2, face, points.ravel().tolist())[0]).reshape(-1, 3)
    return float(np.linalg.norm(closest - points, axis=1).max())


def _curve_points(gmsh, curve: int, count: int):
    """(arc-length fractions (count,), points (count, 3)) of a CAD curve from its start."""
    low, high = (float(b[0]) for b in gmsh.model.getParametrizationBounds(1, curve))
    t = np.linspace(low, high, DENSE_SAMPLES)
    dense = np.array(gmsh.model.getValue(1, curve, t.tolist())).reshape(-1, 3)
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(dense, axis=0), axis=1))])
    at = np.interp(np.linspace(0.0, length[-1], count), length, t)
    points = np.array(gmsh.model.getValue(1, curve, at.tolist())).reshape(-1, 3)
    return np.interp(at, t, length) / length[-1], points


def _cap_loop(gmsh, faces, first: int, translation) -> dict:
    """The first cap's frame, centroid, boundary loop and holes' loops (module docstring)."""
    normal = _normal(gmsh, faces[first])
    normal = normal if normal @ translation > 0 else -normal
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    e1 = np.cross(helper, normal)
    e1 /= np.linalg.norm(e1)
    frame = np.stack([e1, np.cross(normal, e1)])
    origin = np.array(gmsh.model.occ.getCenterOfMass(2, faces[first]))
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
