"""A closed triangulated surface (STL, OBJ, PLY) split into named patches.

Patches come, in this order of preference, from the ``solid NAME`` blocks of a multi-solid ASCII
STL, from one file per patch (a geometry file lists them), or from the surface's sharp edges:
edges whose dihedral angle (between the two triangles' normals) exceeds ``feature_angle``
degrees (default ``DEFAULT_FEATURE_ANGLE``) cut the surface into patches. Vertices shared by
three or more patches are the patches' corners.
"""

from __future__ import annotations

import io
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError, MeshgenError
from meshgen.run.inputs import InputError, read_input_bytes
from meshgen.run.limits import check_shape_memory

__all__ = [
    "DEFAULT_FEATURE_ANGLE",
    "SURFACE_FORMATS",
    "Surface",
    "check_closed",
    "patch_corners",
    "read_surface",
    "read_surfaces",
    "split_at_sharp_edges",
]

DEFAULT_FEATURE_ANGLE = 40.0  # degrees between neighbouring triangles' normals
WELD_TOLERANCE = 1e-10  # points closer than this times the surface's size are one vertex
SURFACE_FORMATS = (".stl", ".obj", ".ply")
_SOLID = re.compile(rb"^\s*solid[ \t]*([^\r\n]*)$", re.MULTILINE)
_ENDSOLID = re.compile(rb"^\s*endsolid\b", re.MULTILINE)
_VERTEX = re.compile(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)")


@dataclass(frozen=True)
class Surface:
    """A triangulated surface: ``vertices`` (n, 3), ``triangles`` (m, 3), ``labels`` (m,) the
    patch of each triangle (-1 where none yet), ``names`` one per label."""

    vertices: np.ndarray
    triangles: np.ndarray
    labels: np.ndarray
    names: tuple


MAX_SURFACE_BYTES = 2**34  # beyond memory checks: the file's size is checked against memory first


def _read_bytes(path: Path) -> bytes:
    """The bytes of the surface file ``path``: a regular file (``read_input_bytes``: a FIFO or a
    device is never read) whose size fits in memory once read as a surface."""
    try:
        check_shape_memory(os.stat(path).st_size, f"surface file {path}")
    except OSError:
        pass  # read_input_bytes says what is wrong
    except MeshgenError as exc:
        raise GeometryError(str(exc)) from None
    try:
        data = read_input_bytes(path, "surface file", MAX_SURFACE_BYTES)
    except InputError as exc:
        raise GeometryError(str(exc).replace(" cannot be read: it does not exist", " does not exist")) from None
    if not data.strip():
        raise GeometryError(f"surface file {path} is empty")
    return data


def _check_binary_stl(data: bytes, path: Path) -> None:
    """GeometryError unless ``data`` is as long as its binary STL header says: 80 bytes, the
    triangle count (uint32), 50 bytes a triangle."""
    if len(data) < 84:
        raise GeometryError(f"{path} is not an STL file: {len(data)} bytes, shorter than a binary STL's 84-byte header")
    count = int(np.frombuffer(data, dtype="<u4", count=1, offset=80)[0])
    whole, rest = divmod(len(data) - 84, 50)
    if rest:
        raise GeometryError(
            f"{path} is a truncated binary STL: it ends {rest} bytes into triangle {whole + 1} "
            f"({len(data)} bytes; its header counts {count} triangles, {84 + 50 * count} bytes)"
        )
    if whole != count:
        raise GeometryError(
            f"{path}: the binary STL header's triangle count ({count}, {84 + 50 * count} bytes) disagrees with the "
            f"file's size ({len(data)} bytes, {whole} triangles)"
        )


def _ascii_stl_solids(data: bytes, path: Path):
    """[(name, triangle corner points (k, 3, 3))] of the ``solid`` blocks of an ASCII STL."""
    starts = list(_SOLID.finditer(data))
    solids = []
    for index, match in enumerate(starts):
        stop = starts[index + 1].start() if index + 1 < len(starts) else len(data)
        block = data[match.end() : stop]
        end = _ENDSOLID.search(block)
        block = block[: end.start()] if end else block
        try:
            points = np.array(_VERTEX.findall(block), dtype=float)
        except ValueError:
            raise GeometryError(f"{path}: solid {index + 1} has a vertex that is not three numbers") from None
        if not np.all(np.isfinite(points)):
            bad = int(np.flatnonzero(~np.all(np.isfinite(points), axis=1))[0])
            raise GeometryError(
                f"{path}: solid {index + 1}, vertex {bad + 1} is not finite ({', '.join(f'{c:g}' for c in points[bad])})"
            )
        if len(points) == 0 and not block.strip(b" \t\r\n"):
            continue  # an empty solid (some exporters write one per unused region)
        if len(points) == 0 or len(points) % 3:
            raise GeometryError(
                f"{path} is not an STL surface: solid {index + 1} has {len(points)} vertices, not whole triangles"
            )
        name = match.group(1).decode("ascii", "replace").strip().split()[0] if match.group(1).strip() else f"solid{index + 1}"
        solids.append((name, points.reshape(-1, 3, 3)))
    if not solids:
        raise GeometryError(f"{path} is an STL file without triangles")
    return solids


def _weld(corner_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangle corner points (m, 3, 3) -> vertices (n, 3) and triangles (m, 3): points closer than
    ``WELD_TOLERANCE`` times the bounding-box diagonal are one vertex (files written by different
    exporters, or solids written apart, may differ in the last digits), which keeps the
    coordinates of its first occurrence."""
    points = corner_points.reshape(-1, 3)
    size = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0))) or 1.0
    cells = np.round((points - points.min(axis=0)) / (WELD_TOLERANCE * size)).astype(np.int64)
    _, first, inverse = np.unique(cells, axis=0, return_index=True, return_inverse=True)
    return points[first], inverse.reshape(-1, 3)


def read_surfaces(paths, names=None) -> Surface:
    """Read one surface file (``paths`` of one) or one file per patch, welded into one surface.
    A single multi-solid ASCII STL gives one label per solid; any other single file one label
    (-1: to be split at sharp edges)."""
    groups = []  # (name, triangle corner points)
    for index, path in enumerate(paths):
        path = Path(path)
        data = _read_bytes(path)
        suffix = path.suffix.lower()
        if suffix not in SURFACE_FORMATS:
            raise GeometryError(f"{path}: unknown surface format {suffix or '(none)'} (formats: {', '.join(SURFACE_FORMATS)})")
        given = names[index] if names else None
        if suffix == ".stl" and data.lstrip()[:5].lower() == b"solid" and b"facet" in data[:4096]:
            solids = _ascii_stl_solids(data, path)
            if len(paths) > 1:
                groups.append((given or path.stem, np.concatenate([points for _, points in solids])))
            else:
                groups.extend(solids)
            continue
        if suffix == ".stl":
            _check_binary_stl(data, path)
        groups.append((given or path.stem, _trimesh_corners(data, path, suffix)))
    corner_points = np.concatenate([points for _, points in groups])
    vertices, triangles = _weld(corner_points)
    if len(paths) == 1 and len(groups) == 1:
        labels = np.full(len(triangles), -1)
        return Surface(vertices, triangles, labels, ())
    labels = np.repeat(np.arange(len(groups)), [len(points) for _, points in groups])
    return Surface(vertices, triangles, labels, tuple(name for name, _ in groups))


def read_surface(path) -> Surface:
    return read_surfaces([path])


def _trimesh_corners(data: bytes, path: Path, suffix: str) -> np.ndarray:
    """Triangle corner points (m, 3, 3) of a binary STL, OBJ or PLY file's bytes ``data``, read by
    trimesh from memory, with a resolver that refuses every file the data names (an OBJ's
    ``mtllib``, a texture): trimesh never opens a file itself (a FIFO named there would block)."""
    import trimesh

    try:
        mesh = trimesh.load(
            io.BytesIO(data), file_type=suffix.lstrip("."), force="mesh", process=False, resolver=_no_files_resolver()
        )
    except Exception as exc:  # trimesh raises many kinds for a file that is not what it says
        raise GeometryError(
            f"{path} is not a readable {suffix.lstrip('.').upper()} surface: {type(exc).__name__}: {exc}"
        ) from None
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))))
    vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=float)
    if faces.ndim != 2 or len(faces) == 0 or faces.shape[1] != 3:
        raise GeometryError(f"{path} is not a {suffix.lstrip('.').upper()} surface of triangles (none found)")
    if faces.dtype.kind not in "iu" or faces.min() < 0 or faces.max() >= len(vertices):
        bad = int(np.flatnonzero((faces < 0).any(axis=1) | (faces >= len(vertices)).any(axis=1))[0])
        raise GeometryError(
            f"{path}: face {bad + 1} names vertex {int(faces[bad][np.argmax((faces[bad] < 0) | (faces[bad] >= len(vertices)))])} "
            f"but the file has {len(vertices)} vertices (0 to {len(vertices) - 1})"
        )
    if not np.all(np.isfinite(vertices)):
        raise GeometryError(f"{path}: a vertex is not a finite number")
    return vertices[faces]


def _no_files_resolver():
    """A trimesh resolver that opens nothing: every name a surface file gives is refused (trimesh
    then loads the surface without it)."""
    from trimesh.resolvers import Resolver

    class NoFiles(Resolver):
        def __init__(self):
            pass

        def get(self, name):
            raise OSError(f"meshgen does not open files a surface file names ({name})")

        def keys(self):
            return iter(())

        def write(self, name, data):
            raise OSError("read only")

        def namespaced(self, namespace):
            return self

    return NoFiles()


def check_closed(surface: Surface, what: str) -> None:
    """GeometryError unless every edge has exactly two triangles, running it in opposite
    directions (closed, manifold, consistently oriented); the message says how many edges fail
    and where one of them is."""
    vertices, triangles = surface.vertices, surface.triangles
    degenerate = (
        (triangles[:, 0] == triangles[:, 1]) | (triangles[:, 1] == triangles[:, 2]) | (triangles[:, 0] == triangles[:, 2])
    )
    if np.any(degenerate):
        where = vertices[triangles[np.argmax(degenerate), 0]]
        raise GeometryError(
            f"{what}: {int(degenerate.sum())} degenerate triangle(s) (two corners the same point), e.g. at {_point(where)}"
        )
    directed = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    n = len(vertices)
    key = np.minimum(directed[:, 0], directed[:, 1]) * n + np.maximum(directed[:, 0], directed[:, 1])
    unique, first, counts = np.unique(key, return_index=True, return_counts=True)
    for count_test, text in (
        (counts == 1, "open: {k} edge(s) belong to one triangle only"),
        (counts > 2, "not manifold: {k} edge(s) are shared by more than two triangles"),
    ):
        if np.any(count_test):
            a, b = directed[first[np.argmax(count_test)]]
            raise GeometryError(
                f"{what} is {text.format(k=int(count_test.sum()))}, e.g. the edge at {_point(0.5 * (vertices[a] + vertices[b]))}"
            )
    forward = np.unique(directed[:, 0] * n + directed[:, 1], return_counts=True)[1]
    if np.any(forward > 1):
        raise GeometryError(
            f"{what}: its triangles are not consistently oriented ({int((forward > 1).sum())} edge(s) run the same way in both triangles)"
        )


def _point(xyz) -> str:
    return "(" + ", ".join(f"{c:.6g}" for c in xyz) + ")"


def triangle_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    normals = np.cross(
        vertices[triangles[:, 1]] - vertices[triangles[:, 0]], vertices[triangles[:, 2]] - vertices[triangles[:, 0]]
    )
    return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)


def _neighbours(triangles: np.ndarray, n_vertices: int):
    """Pairs of triangles (k, 2) that share an edge (a closed manifold surface: two per edge)."""
    directed = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    owner = np.tile(np.arange(len(triangles)), 3)
    key = np.minimum(directed[:, 0], directed[:, 1]) * n_vertices + np.maximum(directed[:, 0], directed[:, 1])
    order = np.argsort(key, kind="stable")
    key, owner = key[order], owner[order]
    pair = np.flatnonzero(key[1:] == key[:-1])
    return np.column_stack([owner[pair], owner[pair + 1]])


def _components(n: int, pairs: np.ndarray) -> tuple[int, np.ndarray]:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)


def split_at_sharp_edges(surface: Surface, feature_angle: float = DEFAULT_FEATURE_ANGLE) -> Surface:
    """Label the triangles by the patches that the edges sharper than ``feature_angle`` degrees
    cut the surface into; patches named ``patch1`` ... in order of their first triangle."""
    pairs = _neighbours(surface.triangles, len(surface.vertices))
    normals = triangle_normals(surface.vertices, surface.triangles)
    cosine = (normals[pairs[:, 0]] * normals[pairs[:, 1]]).sum(axis=1)
    smooth = pairs[cosine > np.cos(np.radians(feature_angle))]
    count, labels = _components(len(surface.triangles), smooth)
    _, first = np.unique(labels, return_index=True)
    renumber = np.empty(count, dtype=np.int64)
    renumber[np.argsort(first)] = np.arange(count)
    return Surface(surface.vertices, surface.triangles, renumber[labels], tuple(f"patch{k + 1}" for k in range(count)))


def check_patches_connected(surface: Surface, what: str) -> None:
    """GeometryError when a labelled patch is in several pieces."""
    pairs = _neighbours(surface.triangles, len(surface.vertices))
    same = pairs[surface.labels[pairs[:, 0]] == surface.labels[pairs[:, 1]]]
    count, pieces = _components(len(surface.triangles), same)
    for label, name in enumerate(surface.names):
        found = len(np.unique(pieces[surface.labels == label]))
        if found > 1:
            raise GeometryError(f"{what}: patch '{name}' is in {found} separate pieces; each patch must be one connected face")
        if found == 0:
            raise GeometryError(f"{what}: patch '{name}' has no triangles")


def patch_corners(surface: Surface) -> list[set]:
    """Per patch, the set of its vertices that three or more patches share (its corners)."""
    n = len(surface.vertices)
    per_vertex = np.unique(np.column_stack([surface.triangles.ravel(), np.repeat(surface.labels, 3)]), axis=0)
    patch_count = np.bincount(per_vertex[:, 0], minlength=n)
    corner = patch_count[per_vertex[:, 0]] >= 3
    corners = [set() for _ in surface.names]
    for vertex, label in per_vertex[corner].tolist():
        corners[label].add(vertex)
    return corners
