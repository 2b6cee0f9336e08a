"""Surfaces of a topology file (``surfaces:``) and the projection of its faces and edges onto them.

A surface is a map X (N, dim) -> its closest points (N, dim): ``sphere`` {center, radius} (2D: a
circle), ``cylinder`` {axis, point, radius} (2D: {point, radius}, a circle), ``torus`` {center,
axis, major, minor} (a bent pipe's wall: the tube of radius minor round the circle of radius major
about the axis), ``plane`` {point, normal} and ``file`` {file: part.stl} (.stl, .obj, .ply; 3D: the closest point on the triangulation)
or {file: part.step, face: N} (3D: OCC's closest point on the CAD file's face N, in meshgen's CAD
process, ``meshgen.geometry.shapes.cad_process``). A face with
``project: NAME`` has its vertices, its edges and (3D) its interior projected; a vertex or edge on
faces of several surfaces goes to their intersection (alternating projection). ``projected``
returns the vertices and edge curves moved; the block maps of ``meshgen.geometry.topology``
project their faces' interior points.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError, did_you_mean
from meshgen.geometry.shapes.assemble import CAD_FORMATS
from meshgen.geometry.shapes.cad_process import cad_face_projection
from meshgen.geometry.shapes.surface_patches import SURFACE_FORMATS, read_surface

__all__ = ["REACH", "SURFACE_KINDS", "Surface", "on_surfaces", "projected", "read_surfaces"]

SURFACE_KINDS = ("sphere", "cylinder", "torus", "plane", "file")
_KEYS = {"sphere": ("center", "radius"), "cylinder": ("axis", "point", "radius"), "plane": ("point", "normal")}
_KEYS["torus"] = ("center", "axis", "major", "minor")
REACH = 0.1  # a face farther than this (relative to its block's size) from its surface is not on it
_CHUNK = 4096  # query points per batch of the STL search


@dataclass(frozen=True)
class Surface:
    """A named surface: ``project`` maps points (N, dim) to their closest points on it (N, dim)."""

    name: str
    kind: str
    project: object


def read_surfaces(path, value, dim: int) -> dict:
    """{name: Surface} of the topology file's ``surfaces`` mapping (GeometryError per problem);
    a ``file`` is read relative to the topology file ``path``."""
    where = f"topology file {path}: surfaces"
    if not isinstance(value, dict):
        raise GeometryError(f"{where} must map names to one of {', '.join(SURFACE_KINDS)}")
    surfaces = {}
    for name, entry in value.items():
        said = f"{where}: '{name}'"
        kinds = [k for k in SURFACE_KINDS if isinstance(entry, dict) and k in entry]
        if not isinstance(entry, dict) or len(kinds) != 1:
            given = ", ".join(map(str, entry)) if isinstance(entry, dict) else repr(entry)[:60]
            hint = did_you_mean(given, SURFACE_KINDS) if isinstance(entry, dict) and len(entry) == 1 else ""
            raise GeometryError(f"{said} needs one surface kind ({', '.join(SURFACE_KINDS)}), got {given}{hint}")
        kind = kinds[0]
        if kind == "file":
            surfaces[str(name)] = Surface(str(name), kind, _file_surface(path, said, entry, dim))
            continue
        if len(entry) != 1 or not isinstance(entry[kind], dict):
            raise GeometryError(f"{said}: {kind} must be a mapping ({', '.join(_KEYS[kind])})")
        surfaces[str(name)] = Surface(str(name), kind, _analytic(said, kind, entry[kind], dim))
    return surfaces


def _vector(said: str, key: str, value, dim: int) -> np.ndarray:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        array = np.zeros(0)
    if array.shape != (dim,) or not np.all(np.isfinite(array)):
        raise GeometryError(f"{said}: {key} must be {dim} numbers, got {value!r}"[:200])
    return array


def _analytic(said: str, kind: str, spec: dict, dim: int):
    allowed = ("point", "radius") if kind == "cylinder" and dim == 2 else _KEYS[kind]
    for key in spec:
        if key not in allowed:
            raise GeometryError(
                f"{said}: unknown key '{key}' in {kind} (keys: {', '.join(allowed)}){did_you_mean(str(key), allowed)}"
            )
    for key in allowed:
        if key not in spec:
            raise GeometryError(f"{said}: {kind} needs '{key}' ({', '.join(allowed)})")
    if kind == "plane":
        point, normal = _vector(said, "point", spec["point"], dim), _vector(said, "normal", spec["normal"], dim)
        if not np.linalg.norm(normal) > 0:
            raise GeometryError(f"{said}: the plane's normal is zero")
        normal = normal / np.linalg.norm(normal)
        return lambda X: X - ((X - point) @ normal)[:, None] * normal
    for key in ("radius", "major", "minor"):
        value = spec.get(key, 1.0)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
            raise GeometryError(f"{said}: {kind} {key} must be a positive number, got {value!r}"[:200])
    if kind == "torus" and dim != 3:
        raise GeometryError(f"{said}: a torus needs a 3D topology")
    center = _vector(said, "point" if kind == "cylinder" else "center", spec["point" if kind == "cylinder" else "center"], dim)
    axis = np.zeros(dim)
    if kind in ("cylinder", "torus") and dim == 3:
        axis = _vector(said, "axis", spec["axis"], dim)
        if not np.linalg.norm(axis) > 0:
            raise GeometryError(f"{said}: the cylinder's axis is zero")
        axis = axis / np.linalg.norm(axis)
    spare = np.eye(dim)[np.argmin(np.abs(axis))]  # a direction for points on the axis

    def unit(v):
        length = np.linalg.norm(v, axis=1, keepdims=True)
        return np.where(length > 0, v / np.where(length > 0, length, 1.0), spare)

    if kind == "torus":  # the closest point of the ring (the tube's centre line), then of the tube about it
        major, minor = float(spec["major"]), float(spec["minor"])

        def project(X):
            X = np.asarray(X, float)
            d = X - center
            ring = center + major * unit(d - (d @ axis)[:, None] * axis)
            return ring + minor * unit(X - ring)

        return project
    radius = float(spec["radius"])

    def project(X):
        d = np.asarray(X, float) - center
        along = (d @ axis)[:, None] * axis
        return center + along + radius * unit(d - along)

    return project


def _file_surface(path, said: str, entry: dict, dim: int):
    """The closest-point map of the triangulated surface ``entry['file']`` (3D only)."""
    for key in entry:
        if key not in ("file", "face"):
            raise GeometryError(
                f"{said}: unknown key '{key}' in a file surface (keys: file, face){did_you_mean(str(key), ('file', 'face'))}"
            )
    name = Path(str(entry["file"]))
    file = name if name.is_absolute() else Path(path).parent / name
    if dim != 3:
        raise GeometryError(f"{said}: a file surface needs a 3D topology (2D: sphere, cylinder or plane)")
    if file.suffix.lower() in CAD_FORMATS:
        face = entry.get("face")
        if isinstance(face, bool) or not isinstance(face, int) or face < 1:
            raise GeometryError(f"{said}: a CAD file surface needs 'face': the face's number (1, 2, ...), got {face!r}"[:200])
        if not file.is_file():
            raise GeometryError(f"{said}: no file {file}")
        return cad_face_projection(file.resolve(), face)
    if "face" in entry:
        raise GeometryError(f"{said}: 'face' is for a CAD file ({', '.join(CAD_FORMATS)}); {name} is a triangulated surface")
    if file.suffix.lower() not in SURFACE_FORMATS:
        raise GeometryError(
            f"{said}: {name} is no triangulated surface ({', '.join(SURFACE_FORMATS)}) and no CAD file ({', '.join(CAD_FORMATS)})"
        )
    if not file.is_file():
        raise GeometryError(f"{said}: no file {file}")
    import trimesh
    from scipy.spatial import cKDTree

    try:
        surface = read_surface(file)  # meshgen's checked reading: limits, no file named inside it opened
    except GeometryError as exc:
        raise GeometryError(f"{said}: {exc}") from None
    triangles = surface.vertices[surface.triangles]
    centroids = triangles.mean(axis=1)
    reach = float(np.max(np.linalg.norm(triangles - centroids[:, None], axis=2)))
    tree = cKDTree(centroids)

    def project(X):
        X = np.asarray(X, float)
        out = np.empty_like(X)
        for start in range(0, len(X), _CHUNK):  # batches of points: bounded candidate lists
            Q = X[start : start + _CHUNK]
            nearest, _ = tree.query(Q)
            lists = tree.query_ball_point(Q, nearest + reach)
            counts = np.fromiter((len(c) for c in lists), int, len(lists))
            candidates = np.concatenate([np.asarray(c, int) for c in lists])
            owners = np.repeat(np.arange(len(Q)), counts)
            points = trimesh.triangles.closest_point(triangles[candidates], Q[owners])
            distance = np.linalg.norm(points - Q[owners], axis=1)
            order = np.lexsort((distance, owners))
            first = order[np.concatenate([[0], np.cumsum(counts)[:-1]])]
            out[start : start + len(Q)] = points[first]
        return out

    return project


def on_surfaces(surfaces: list, X: np.ndarray, size: float) -> np.ndarray:
    """``X`` (N, dim) projected onto all of ``surfaces`` (their intersection: alternating
    projection until it moves less than 1e-14 of ``size``, at most 200 rounds)."""
    X = np.asarray(X, float)
    if len(surfaces) == 1:
        return surfaces[0].project(X)
    for _ in range(200):  # rounds of projection, each over all points
        before = X
        for surface in surfaces:
            X = surface.project(X)
        if np.max(np.abs(X - before), initial=0.0) <= 1e-14 * size:
            break
    return X


def _check(surfaces, where: str, samples: np.ndarray, size: float) -> np.ndarray:
    moved = on_surfaces(surfaces, samples, size)
    gap = float(np.max(np.linalg.norm(moved - samples, axis=1)))
    if gap > REACH * size:
        names = " and ".join(f"'{s.name}'" for s in surfaces)
        raise GeometryError(
            f"{where}: surface {names} does not contain it: it is {gap:.3g} away (above {REACH:g} of its block's size {size:.3g})"
        )
    return moved


def projected(topology, curves: dict) -> tuple[np.ndarray, dict]:
    """(vertex points (V, dim), {(i, j): curve}) of ``topology`` with every projected face's
    vertices and edges moved onto its surface (edges of several surfaces: their intersection; the
    other edges at a moved vertex follow it);
    GeometryError for a face or edge farther than ``REACH`` of its block's size from its surface."""
    points, names = topology.points.copy(), topology.vertex_names
    where = f"topology file {topology.path}"
    on_edge: dict = {}
    for face, name in topology.projections.items():
        for edge in curves:
            if set(edge) <= face:
                on_edge.setdefault(edge, []).append(name)
    for edge, name in topology.edge_projections.items():
        on_edge.setdefault(edge, []).append(name)
    on_vertex: dict = {}
    for (i, j), listed in on_edge.items():
        for v in (i, j):
            on_vertex.setdefault(v, set()).update(listed)

    def block_size(vertices) -> float:  # the largest extent of the blocks holding these vertices
        rows = [row for row in topology.blocks if set(vertices) <= set(int(v) for v in row)]
        return max((float(np.ptp(points[row], axis=0).max()) for row in rows), default=1.0)

    for face, name in topology.projections.items():
        listed = sorted(face)
        _check(
            [topology.surfaces[name]],
            f"{where}: the face ({' '.join(names[v] for v in listed)})",
            points[listed],
            block_size(face),
        )
    moved = points.copy()
    for v, listed in on_vertex.items():  # a loop over the projected vertices
        surfaces = [topology.surfaces[n] for n in sorted(listed)]
        moved[v] = on_surfaces(surfaces, points[v : v + 1], float(np.ptp(points, axis=0).max()))[0]
    result = {(i, j): _shifted(function, moved[i] - points[i], moved[j] - points[j]) for (i, j), function in curves.items()}
    t = np.linspace(0.0, 1.0, 17)
    for (i, j), listed in on_edge.items():
        surfaces = [topology.surfaces[n] for n in sorted(set(listed))]
        size = block_size((i, j))
        _check(surfaces, f"{where}: the edge {names[i]}-{names[j]}", curves[i, j](t), size)
        result[i, j] = _projected_curve(curves[i, j], surfaces, points[i], points[j], moved[i], moved[j], size)
    return moved, result


def _shifted(function, shift_a, shift_b):
    """The curve ``function`` with its ends moved by ``shift_a`` and ``shift_b`` (linearly between):
    an edge off the surfaces that ends at a projected vertex."""
    if not (np.any(shift_a) or np.any(shift_b)):
        return function
    return lambda t: function(t) + (1.0 - np.asarray(t, float)[:, None]) * shift_a + np.asarray(t, float)[:, None] * shift_b


def _projected_curve(function, surfaces, a, b, new_a, new_b, size: float):
    """The curve ``function`` projected, its ends shifted onto the projected vertices."""

    def curve(t):
        t = np.asarray(t, float)[:, None]
        X = on_surfaces(surfaces, function(t[:, 0]), size)
        ends = on_surfaces(surfaces, np.stack([a, b]), size)
        X = X + (1.0 - t) * (new_a - ends[0]) + t * (new_b - ends[1])
        return on_surfaces(surfaces, X, size)

    return curve
