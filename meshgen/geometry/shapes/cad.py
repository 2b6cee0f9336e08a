"""A Geometry from a CAD solid (STEP, IGES, BREP) read by gmsh's OpenCASCADE kernel.

The solid (or closed shell) must be bounded by six faces of four corners each. Corners are the
CAD vertices; each cube edge is its CAD curve, spaced by arc length from its lower corner; a face
point is the face's own surface evaluated (``gmsh.model.getValue``) at the Coons patch, in the
face's (u, v) parameters, of its four sides (``reparametrizeOnSurface``), so every boundary node
lies on the true CAD surface, not on a tessellation of it.

gmsh is imported only here, in the process that reads CAD files (``cad_process``: OpenCASCADE
can crash on a malformed file, and that must not take meshgen with it). It is global state: meshgen initialises it
once if nobody has (without reading the user's gmsh configuration, without installing its
interrupt handler), keeps one gmsh model per file (named by the file's content hash) and makes
that model current before every evaluation; if gmsh was finalised meanwhile, the file is read
again.
"""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry import cube
from meshgen.geometry.shapes.faces import (
    BoundaryPieces,
    assign_faces,
    corner_of_cube,
    edge_ends,
    face_corners,
    faces_from_corners,
    signed_volume,
    swap_eta,
)

__all__ = ["CadBlock", "closest_on_face", "gmsh_model", "quiet_stdout", "read_cad_block"]

ARC_SAMPLES = 2001  # parameter samples per curve for its arc length
SIDE_SAMPLES = 513  # arc-length samples per face side for its (u, v) trace
SEW_TOLERANCES = (1e-6, 1e-5, 1e-4)  # an IGES file's faces sewn at these, relative to its size, in turn


def _gmsh():
    try:
        import gmsh
    except ImportError:
        raise GeometryError("reading CAD files (STEP, IGES, BREP) needs the gmsh Python package: pip install gmsh") from None
    if not gmsh.isInitialized():
        gmsh.initialize(readConfigFiles=False, interruptible=False)
        gmsh.option.setNumber("General.Terminal", 0)
    return gmsh


def gmsh_model(path: Path, model: str):
    """gmsh with the file ``path`` loaded as model ``model`` and made current (read once)."""
    gmsh = _gmsh()
    if model in gmsh.model.list():
        gmsh.model.setCurrent(model)
        return gmsh
    gmsh.model.add(model)
    if path.suffix.lower() not in (".iges", ".igs"):
        _import(gmsh, path, {})
        return gmsh
    # An IGES file keeps no topology: sew its faces along shared edges and make a solid of the
    # closed shell (not for STEP and BREP, whose solids sewing would dissolve). OCC rebuilds an
    # edge from the face's parameter-space curve when it cannot use the 3D one (a full circle on a
    # surface of revolution: a B-spline within 1e-5 of it), which the neighbour's exact edge meets
    # only that closely: no solid at gmsh's tolerance, so sew again at SEW_TOLERANCES (relative
    # to the part's size) until one closes (``sweep_read`` puts such edges' points back on both faces).
    sew = {"Geometry.OCCSewFaces": 1.0, "Geometry.OCCMakeSolids": 1.0}
    _import(gmsh, path, sew)
    if gmsh.model.getEntities(3) or not gmsh.model.getEntities(2):
        return gmsh
    box = np.array(gmsh.model.getBoundingBox(-1, -1)).reshape(2, 3)
    size = float(np.linalg.norm(box[1] - box[0]))
    for tolerance in SEW_TOLERANCES:
        gmsh.model.remove()
        gmsh.model.add(model)
        _import(gmsh, path, {**sew, "Geometry.Tolerance": tolerance * size})
        if gmsh.model.getEntities(3):
            break
    return gmsh


def _import(gmsh, path: Path, options: dict) -> None:
    """Read ``path`` into the current (empty) model, the gmsh ``options`` set meanwhile."""
    previous = {name: gmsh.option.getNumber(name) for name in options}
    try:
        for name, value in options.items():
            gmsh.option.setNumber(name, value)
        with quiet_stdout():  # OCC's readers print to the process's stdout
            gmsh.model.occ.importShapes(str(path))
        gmsh.model.occ.synchronize()
    except Exception as exc:  # gmsh raises a bare Exception with its last error
        gmsh.model.remove()
        message = " ".join(str(exc).split()) or "gmsh could not read it"
        raise GeometryError(f"{path} is not a readable {path.suffix.lstrip('.').upper()} file: {message}") from None
    finally:
        for name, value in previous.items():
            gmsh.option.setNumber(name, value)


def closest_on_face(path, face: int, points: np.ndarray) -> np.ndarray:
    """The closest points (N, 3) of ``points`` (N, 3) on the face numbered ``face`` (gmsh's
    surface tag, 1, 2, ...) of the CAD file ``path``: OCC's projection, all points in one call."""
    path = Path(path)
    gmsh = gmsh_model(path, f"faces of {path}")
    tags = sorted(tag for _, tag in gmsh.model.getEntities(2))
    if face not in tags:
        raise GeometryError(
            f"{path} has no face {face} (its faces: {', '.join(map(str, tags[:12]))}{' ...' if len(tags) > 12 else ''})"
        )
    points = np.ascontiguousarray(points, dtype=float).reshape(-1, 3)
    if len(points) == 0:
        return points
    closest, _ = gmsh.model.getClosestPoint(2, face, points.ravel().tolist())
    return np.asarray(closest, dtype=float).reshape(-1, 3)


@contextlib.contextmanager
def quiet_stdout():
    """File descriptor 1 sent to the null device for the duration (C++ code writes there)."""
    sys.stdout.flush()
    try:
        saved = os.dup(1)
    except OSError:  # no stdout to redirect
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 1)
            yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)


class CadBlock:
    """A CAD solid with its six faces assigned to the cube's faces: ``names`` per face (CAD face
    names, else face1..face6), ``assignment`` cube face -> face index, ``pieces`` the boundary map,
    ``volume`` the solid's volume (OCC's mass), ``face_tags`` gmsh's surface tags."""

    def __init__(self, names, assignment, pieces, volume, face_tags, box):
        self.names, self.assignment, self.pieces = names, assignment, pieces
        self.volume, self.face_tags, self._box = volume, face_tags, box

    def extent(self):
        return self._box


def _solid_faces(gmsh, path: Path) -> tuple[list[int], float]:
    volumes = gmsh.model.getEntities(3)
    surfaces = [tag for _, tag in gmsh.model.getEntities(2)]
    if len(volumes) > 1:
        raise GeometryError(f"{path} holds {len(volumes)} solids; a block is one solid")
    if volumes:
        faces = [abs(tag) for dim, tag in gmsh.model.getBoundary(volumes, oriented=False) if dim == 2]
        volume = gmsh.model.occ.getMass(3, volumes[0][1])
    elif surfaces and path.suffix.lower() in (".iges", ".igs"):
        raise GeometryError(
            f"{path}: its {len(surfaces)} face(s) do not sew into a closed solid (gaps wider than "
            f"{SEW_TOLERANCES[-1]:g} of its size, or an open surface)"
        )
    elif surfaces:
        faces, volume = surfaces, float("nan")
    else:
        raise GeometryError(f"{path} holds no solid and no faces")
    return faces, volume


def _face_topology(gmsh, faces: list[int], path: Path):
    """Per face: its boundary curves (tags, in loop order) and the set of its corner points."""
    curves, corner_sets = [], []
    for face in faces:
        loop = [abs(tag) for _, tag in gmsh.model.getBoundary([(2, face)], oriented=False, combined=False)]
        points = set()
        for curve in loop:
            points |= {abs(tag) for _, tag in gmsh.model.getBoundary([(1, curve)], oriented=False, combined=False)}
        curves.append(loop)
        corner_sets.append(points)
    if len(faces) != 6 or any(len(c) != 4 for c in curves):
        listed = ", ".join(str(len(c)) for c in curves)
        raise GeometryError(
            f"{path}: the solid has {len(faces)} face(s) with ({listed}) side(s); a block needs six faces of four corners each"
        )
    return curves, corner_sets


def _curve_between(curves, corner_a: int, corner_b: int, gmsh):
    """(curve tag, reversed) of the curve from CAD point ``corner_a`` to ``corner_b``."""
    for loop in curves:
        for curve in loop:
            ends = [abs(t) for _, t in gmsh.model.getBoundary([(1, curve)], oriented=False, combined=False)]
            if ends == [corner_a, corner_b]:
                return curve, False
            if ends == [corner_b, corner_a]:
                return curve, True
    raise GeometryError(f"no CAD curve joins the corners {corner_a} and {corner_b}")


class _Curve:
    """A CAD curve by normalised arc length from one end: ``parameter(s)`` the curve's own."""

    def __init__(self, gmsh, tag: int, reversed_: bool):
        low, high = (float(b[0]) for b in gmsh.model.getParametrizationBounds(1, tag))
        t = np.linspace(low, high, ARC_SAMPLES)
        if reversed_:
            t = t[::-1]
        points = np.array(gmsh.model.getValue(1, tag, t.tolist())).reshape(-1, 3)
        length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
        self.tag, self.t, self.fraction = tag, t, length / length[-1]

    def parameter(self, s) -> np.ndarray:
        return np.interp(np.asarray(s, dtype=float), self.fraction, self.t)


def read_cad_block(path, given_faces: dict | None = None, content_hash: str = "", given_corners=None) -> CadBlock:
    """Read a CAD file and assign its six faces to the cube's (``faces.assign_faces``), in this
    process: meshgen calls it only in the CAD reader's own process (``cad_process.cad_block``)."""
    path = Path(path)
    model = f"meshgen-{content_hash[:16]}"
    gmsh = gmsh_model(path, model)
    faces, volume = _solid_faces(gmsh, path)
    curves, corner_sets = _face_topology(gmsh, faces, path)
    names = []
    for k, face in enumerate(faces):
        name = gmsh.model.getEntityName(2, face).split("/")[-1].strip().replace(" ", "_")
        names.append(name if name and name not in names else f"face{k + 1}")
    areas = [gmsh.model.occ.getMass(2, face) for face in faces]
    what = str(path)
    if given_corners is not None:
        positions = {tag: np.array(gmsh.model.getValue(0, tag, [])) for tag in set().union(*corner_sets)}
        given_faces = faces_from_corners(corner_sets, positions, given_corners, names, what)
    assignment = assign_faces(corner_sets, areas, names, what, given_faces)
    corners = corner_of_cube(assignment, corner_sets, what)
    ensure = _Ensure(path, model)
    corner_points = {ijk: np.array(gmsh.model.getValue(0, tag, [])) for ijk, tag in corners.items()}
    edge_curves = {}
    for edge in cube.edges():
        start, stop = edge_ends(edge, corners)
        edge_curves[edge.name] = _Curve(gmsh, *_curve_between(curves, start, stop, gmsh))
    edges = {name: _edge_map(ensure, curve) for name, curve in edge_curves.items()}
    face_maps = {}
    for face in cube.faces(3):
        tag = faces[assignment[face.name]]
        c00, c10, c11, c01 = face_corners(face, corners)
        sides = []  # (the side's curve from its first to its second corner) for p = 0, p = 1, q = 0, q = 1
        for a, b in ((c00, c01), (c10, c11), (c00, c10), (c01, c11)):
            sides.append(_side_trace(gmsh, _Curve(gmsh, *_curve_between(curves, a, b, gmsh)), tag))
        face_maps[face.name] = _face_map(ensure, tag, sides)
    box = np.array(gmsh.model.getBoundingBox(-1, -1)).reshape(2, 3)
    pieces = BoundaryPieces(face_maps, edges, corner_points, content_hash=content_hash, what=what)
    if signed_volume(pieces) < 0:
        if given_faces:
            raise GeometryError(
                f"{what}: the face assignment is left-handed (the mapped cube turns inside out); swap two opposite faces, "
                "e.g. eta0 and eta1"
            )
        assignment = swap_eta(assignment)
        pieces.reflect_eta = True
    return CadBlock(tuple(names), assignment, pieces, volume, tuple(faces), (box[0], box[1]))


class _Ensure:
    """Makes the file's gmsh model current (reading it again if gmsh was finalised meanwhile)."""

    def __init__(self, path: Path, model: str):
        self.path, self.model = path, model

    def __call__(self):
        return gmsh_model(self.path, self.model)


def _edge_map(ensure, curve: _Curve):
    def edge(s):
        gmsh = ensure()
        return np.array(gmsh.model.getValue(1, curve.tag, curve.parameter(s).tolist())).reshape(-1, 3)

    return edge


def _side_trace(gmsh, curve: _Curve, face: int) -> np.ndarray:
    """(SIDE_SAMPLES, 2) the face's (u, v) along a side at uniform arc-length fractions."""
    s = np.linspace(0.0, 1.0, SIDE_SAMPLES)
    uv = gmsh.model.reparametrizeOnSurface(1, curve.tag, curve.parameter(s).tolist(), face)
    return np.array(uv).reshape(-1, 2)


def _along(trace: np.ndarray, s: np.ndarray) -> np.ndarray:
    grid = np.linspace(0.0, 1.0, len(trace))
    return np.column_stack([np.interp(s, grid, trace[:, c]) for c in range(2)])


def _face_map(ensure, tag: int, sides):
    left, right, bottom, top = sides  # p = 0, p = 1 (along q); q = 0, q = 1 (along p)
    c00, c01, c10, c11 = left[0], left[-1], right[0], right[-1]

    def face(pq):
        p, q = pq[:, :1], pq[:, 1:]
        uv = (
            (1 - p) * _along(left, pq[:, 1])
            + p * _along(right, pq[:, 1])
            + (1 - q) * _along(bottom, pq[:, 0])
            + q * _along(top, pq[:, 0])
            - ((1 - p) * (1 - q) * c00 + p * (1 - q) * c10 + (1 - p) * q * c01 + p * q * c11)
        )
        gmsh = ensure()
        return np.array(gmsh.model.getValue(2, tag, uv.ravel().tolist())).reshape(-1, 3)

    return face
